"""The payloads the exporter's Zenoh relay hands one worker, in memory both processes map: no pipe copies.

Through a pipe, a 4 kB payload is copied into the pickle, into the kernel, out of it and out of the
pickle again: 6-11 µs a sample of the two processes' CPU, measured beside 2.0-2.3 µs when the relay
copies it into a ring of memory the worker maps and the pipe carries only the batch's keys and lengths
(bench/README.md, 2026-12-02). The relay writes each batch's payloads one after another into the ring
and the worker, once it has copied them out, tells how far it has read in the ring's header; what it has
not read yet is never overwritten. A batch that does not fit goes down the pipe whole, as before.

Positions count bytes written since the ring was made and never wrap; a batch starts at the ring's
beginning again rather than wrap around its end. The header's 8 bytes are written by the worker only, and
read by the relay only: an older value read there only makes the ring seem fuller than it is.
"""

from __future__ import annotations

import mmap
import os
import struct
import tempfile
import weakref
from collections.abc import Sequence

HEADER_BYTES = 64  # the reader's position first; the rest keeps the payloads off the header's cache line
# A worker's batch gathers for 50 ms: at 10,000 robots of 4 kB at 1 Hz shared by two workers, 1 MB. The
# ring holds four; larger batches (a first look's backlog) take the pipe. Both processes map it whole.
DEFAULT_RING_BYTES = 4 << 20
_POSITION = struct.Struct("<Q")


class SharedRing:
    """`size` bytes of payloads in a memory file: the relay places batches, the worker takes them."""

    def __init__(self, descriptor: int, size: int) -> None:
        """Map the ring of `size` bytes in the memory file open as `descriptor` (made by `create`)."""
        self._descriptor = descriptor
        self.size = size
        self._map = mmap.mmap(descriptor, HEADER_BYTES + size)
        self._written = 0  # the writer's own position
        self._close = weakref.finalize(self, os.close, descriptor)

    @classmethod
    def create(cls, size: int = DEFAULT_RING_BYTES) -> SharedRing:
        """A new, empty ring of `size` bytes."""
        if hasattr(os, "memfd_create"):
            descriptor = os.memfd_create("overseer-relay", os.MFD_CLOEXEC)
        else:  # not Linux: a file no one else can open
            descriptor, path = tempfile.mkstemp(prefix="overseer-relay-")
            os.unlink(path)
        os.ftruncate(descriptor, HEADER_BYTES + size)
        return cls(descriptor, size)

    def fileno(self) -> int:
        """The memory file's descriptor, to pass to the worker."""
        return self._descriptor

    def close(self) -> None:
        """Close the memory file's descriptor; the mapping stays until no one holds the ring."""
        self._close()

    def place(self, payloads: Sequence[bytes]) -> tuple[int, int] | None:
        """Copy `payloads` into the ring one after another: their start and end; None if they do not fit."""
        needed = sum(len(payload) for payload in payloads)
        start = self._written
        if start % self.size + needed > self.size:
            start += self.size - start % self.size  # the batch begins the ring again rather than wrap
        if start + needed - self._read_position() > self.size:
            return None
        offset = HEADER_BYTES + start % self.size
        ring = self._map
        for payload in payloads:
            end = offset + len(payload)
            ring[offset:end] = payload
            offset = end
        self._written = start + needed
        return start, self._written

    def take(self, start: int, lengths: Sequence[int]) -> list[bytes]:
        """Copies of the payloads of `lengths` bytes each placed from `start` on."""
        offset = HEADER_BYTES + start % self.size
        ring = self._map
        taken = []
        for length in lengths:
            end = offset + length
            taken.append(ring[offset:end])
            offset = end
        return taken

    def release(self, end: int) -> None:
        """Let the relay write over everything placed before `end`: the worker has taken it."""
        _POSITION.pack_into(self._map, 0, end)

    def _read_position(self) -> int:
        position: int = _POSITION.unpack_from(self._map, 0)[0]
        return position
