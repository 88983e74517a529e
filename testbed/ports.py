"""Free loopback ports and DDS domain ids for tests that run side by side."""

from __future__ import annotations

import fcntl
import os
import socket
import tempfile
import threading
from pathlib import Path
from typing import IO

_lock = threading.Lock()


def free_port() -> int:
    """A TCP port on 127.0.0.1 that nothing listens on right now."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as sock:
        sock.bind(("127.0.0.1", 0))
        port: int = sock.getsockname()[1]
        return port


def fresh_domain_id(count: int = 1) -> int:
    """The first of `count` consecutive DDS domain ids that no other test, here or in another process, uses.

    Domain ids map to UDP ports (7400 + 250 x id), so distinct ids keep concurrent tests apart. A lock
    file per id, held until this process exits, keeps other test runs on the same machine off it.
    """
    _LOCK_DIR.mkdir(exist_ok=True)
    with _lock:
        first = 1 + (os.getpid() * 37) % (_MAX_DOMAIN - count)
        for step in range(_MAX_DOMAIN):
            start = 1 + (first + step) % (_MAX_DOMAIN - count)
            block = range(start, start + count)
            if any(domain in _held for domain in block):
                continue
            locked = [handle for domain in block if (handle := _try_lock(domain)) is not None]
            if len(locked) == count:
                _held.update(zip(block, locked, strict=True))
                return start
            for handle in locked:
                handle.close()
    raise RuntimeError("no free DDS domain id left for tests")


_MAX_DOMAIN = 232
_LOCK_DIR = Path(tempfile.gettempdir()) / "overseer-test-dds-domains"
_held: dict[int, IO[bytes]] = {}


def _try_lock(domain: int) -> IO[bytes] | None:
    handle = (_LOCK_DIR / f"{domain}.lock").open("ab")
    try:
        fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        handle.close()
        return None
    return handle
