"""Freed heap memory handed back to the system: glibc keeps it after a backlog drains, or a large render.

When the ingest falls behind (a fleet heard for the first time, 10,000 robots' first arrays at once),
the samples waiting for it pile up, tens of thousands of them, a few kB each (`sources/paced_drain.py`,
`sources/zenoh/outbox.py`), and so do the events waiting for their database (`history/store.py`).
Once they are read, the heap they were allocated from stays the process's: glibc returns memory to the
system only from the top of a heap, and the freed samples lie between the model's live objects. At
10,000 robots x 50 components over Zenoh (`bench.bench_scale`, one worker) that was 0.4-0.9 kB a
component more than without the backlog, for good. `malloc_trim` gives every free page back, from
every thread's heap. It holds each heap's lock while it works on it (56-64 ms in all at that size), so a
thread allocating meanwhile waits: it runs once a minute, and once a large backlog has drained, not after
every batch.

glibc also gives each new thread a heap (an arena) of its own, up to eight a core, and the exporter's
process runs many (Zenoh's, the relay's, the HTTP server's): each keeps what it freed. Two arenas took
the exporter's process from 133-136 MB to 111-112 MB at 3,000 robots with two workers, for the same CPU
(`limit_heap_arenas`); `MALLOC_ARENA_MAX` or glibc's tunables, when an operator sets them, decide instead.

A scrape of 10,000 robots renders megabytes at a time; glibc's moving bound for mapping a block on its
own soon takes such blocks from the heap instead, where they stay once freed (`map_large_blocks`).
A scrape left 35-40 MB more resident in the exporter's process at 10,000 robots until the minute's
trim, none of it live (freed blocks, most likely those its answer was built from: the workers' parts):
a large answer, once written, is followed by a trim of its own (`trim_after_answer`).
"""

from __future__ import annotations

import ctypes
import logging
import os
import threading
from collections.abc import Callable
from typing import Any

log = logging.getLogger(__name__)

TRIM_INTERVAL_SECONDS = 60.0
# Items once waiting together (samples, ~80 MB of them; events) after which their heap is handed back.
TRIM_AFTER_BACKLOG = 20_000
# A `/metrics` answer this large is followed by a trim (gzip: roughly 500 to 2,500 robots, as values go).
TRIM_AFTER_ANSWER_BYTES = 1 << 20
HEAP_ARENAS = 2
MMAP_THRESHOLD_BYTES = 1 << 20
_M_MMAP_THRESHOLD = -3  # mallopt's parameters (malloc.h)
_M_ARENA_MAX = -8
_FIXING = ("mmap_threshold", "trim_threshold", "top_pad", "mmap_max")  # glibc settings that fix the bounds


def _c_function(name: str, *argtypes: type[ctypes._SimpleCData[Any]]) -> Callable[..., int] | None:
    """The C library's function `name` returning an int (glibc's), or None where it has none (musl, macOS)."""
    for library in ("libc.so.6", None):  # glibc by its soname, else whatever C library the process has
        try:
            function = getattr(ctypes.CDLL(library), name, None)
        except OSError:
            continue
        if function is not None:
            function.argtypes = list(argtypes)
            function.restype = ctypes.c_int
            found: Callable[..., int] = function
            return found
    return None


# malloc_trim(size_t pad) and mallopt(int param, int value)
_TRIM: Callable[[int], int] | None = _c_function("malloc_trim", ctypes.c_size_t)
_MALLOPT: Callable[[int, int], int] | None = _c_function("mallopt", ctypes.c_int, ctypes.c_int)
_guard = threading.Lock()
_trimming = False  # this process's own trimming thread was started


def trim_heap() -> bool:
    """Give the heap's free pages back to the system; False where the C library cannot."""
    if _TRIM is None:
        return False
    _TRIM(0)  # ctypes lets go of the interpreter lock meanwhile
    return True


def trim_after_answer(length: int) -> bool:
    """Trim once an answer of `length` bytes is written, if it was large; False when no trim was made."""
    return length >= TRIM_AFTER_ANSWER_BYTES and trim_heap()


def shape_heap() -> None:
    """Shape this process's heap before its threads start: few arenas, large blocks mapped on their own."""
    limit_heap_arenas()
    map_large_blocks()


def map_large_blocks(threshold: int = MMAP_THRESHOLD_BYTES) -> bool:
    """Map each block of `threshold` bytes or more on its own, freed to the system; False where left as is.

    glibc maps a block of 128 kB or more on its own, but raises that bound to the size of each such block
    freed, up to 32 MB: after the first scrape, the megabytes of a render's pieces come from the heap, and
    stay the process's between live objects once freed. A fixed bound keeps them mapped; it also keeps
    the bound above which `free` shrinks the heap's top at its 128 kB, where it grew with the other
    before. Left as it is where the C library has no `mallopt`, or where the environment already fixes
    either bound (glibc's `MALLOC_*_` variables or tunables).
    """
    if _MALLOPT is None:
        return False
    tunables = os.environ.get("GLIBC_TUNABLES", "")
    if any(f"MALLOC_{name.upper()}_" in os.environ or f"glibc.malloc.{name}" in tunables for name in _FIXING):
        return False
    return _MALLOPT(_M_MMAP_THRESHOLD, threshold) == 1


def limit_heap_arenas(arenas: int = HEAP_ARENAS) -> bool:
    """Let this process's threads share `arenas` heaps (before they start); False where left as it is.

    Left as it is where the C library has no `mallopt`, or where the environment already says how many
    (`MALLOC_ARENA_MAX`, or `arena_max` in `GLIBC_TUNABLES`).
    """
    if _MALLOPT is None:
        log.debug("no mallopt in this C library: each thread may keep a heap of its own")
        return False
    if "MALLOC_ARENA_MAX" in os.environ or "glibc.malloc.arena_max" in os.environ.get("GLIBC_TUNABLES", ""):
        return False
    return _MALLOPT(_M_ARENA_MAX, arenas) == 1


def trim_heap_every(
    interval: float = TRIM_INTERVAL_SECONDS, stop: threading.Event | None = None
) -> threading.Thread | None:
    """Trim this process's heap every `interval` seconds until `stop` (by default, as long as it runs).

    None where the C library cannot trim, and when this process trims already: one thread is enough.
    """
    if _TRIM is None:
        log.debug("no malloc_trim in this C library: freed memory stays with the process")
        return None
    global _trimming
    with _guard:
        if stop is None and _trimming:
            return None
        _trimming = _trimming or stop is None
    thread = threading.Thread(
        target=_trim_loop, args=(interval, stop or threading.Event()), name="heap-trim", daemon=True
    )
    thread.start()
    return thread


def _trim_loop(interval: float, stop: threading.Event) -> None:
    while not stop.wait(interval):
        trim_heap()
