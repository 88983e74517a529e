"""Freed heap memory handed back to the system every minute: glibc keeps it after a backlog drains.

When the ingest falls behind (a fleet heard for the first time, 10,000 robots' first arrays at once),
Zenoh's receiving threads hold the samples waiting for it, tens of thousands of them, a few kB each.
Once they are read, the heap they were allocated from stays the process's: glibc returns memory to the
system only from the top of a heap, and the freed samples lie between the model's live objects. At
10,000 robots x 50 components over Zenoh (`bench.bench_scale`, one worker) that was 0.4-0.9 kB a
component more than without the backlog, for good. `malloc_trim` gives every free page back, from
every thread's heap; it takes the allocator's locks, so it runs once a minute, not after every sample.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import logging
import threading
import time
from collections.abc import Callable

log = logging.getLogger(__name__)

TRIM_INTERVAL_SECONDS = 60.0


def _glibc_trim() -> Callable[[int], int] | None:
    """The C library's `malloc_trim` (glibc's), or None where it has none (musl, macOS)."""
    name = ctypes.util.find_library("c")
    if name is None:
        return None
    try:
        trim: Callable[[int], int] = ctypes.CDLL(name).malloc_trim
    except (OSError, AttributeError):
        return None
    return trim


_TRIM = _glibc_trim()


def trim_heap() -> bool:
    """Give the heap's free pages back to the system; False where the C library cannot."""
    if _TRIM is None:
        return False
    _TRIM(0)  # ctypes lets go of the interpreter lock meanwhile
    return True


def trim_heap_every(interval: float = TRIM_INTERVAL_SECONDS) -> threading.Thread | None:
    """Trim this process's heap every `interval` seconds for as long as it runs; None where it cannot."""
    if _TRIM is None:
        log.debug("no malloc_trim in this C library: freed memory stays with the process")
        return None
    thread = threading.Thread(target=_trim_loop, args=(interval,), name="heap-trim", daemon=True)
    thread.start()
    return thread


def _trim_loop(interval: float) -> None:
    while True:  # a daemon: it ends with the process
        time.sleep(interval)
        trim_heap()
