"""A file in memory that the exporter and its workers map: made by one, passed to the others by descriptor."""

from __future__ import annotations

import os
import tempfile


def create_memory_file(name: str, size: int) -> int:
    """The descriptor of a new memory file of `size` zero bytes, which only this process can open."""
    if hasattr(os, "memfd_create"):
        descriptor = os.memfd_create(name, os.MFD_CLOEXEC)
    else:  # not Linux: a file no one else can open
        descriptor, path = tempfile.mkstemp(prefix=f"{name}-")
        os.unlink(path)
    try:
        os.ftruncate(descriptor, size)
    except OSError:
        os.close(descriptor)
        raise
    return descriptor
