"""Handing received samples to the ingest a batch at a time: one wake-up for many samples, not one each.

A thread that blocks for every sample wakes once a sample, and on a busy machine (a virtual one above
all) the wake-up and the caches it finds cold by then cost more than the sample's ingest: at 1,000
robots the draining thread spent ~80 µs of CPU a message on work that costs ~25 µs in a tight loop.
So while samples keep coming the thread pauses a little between batches and takes all that gathered;
when they stop, it goes back to blocking, so an idle exporter does not wake at all. Measured at 3,000
robots (`bench.bench_scale`, same run): 129 → 117 µs a message with one worker, 195 → 153 with two.

A source that keeps what waits in buffers of its own can be emptied into a queue of ours between shares
of the work instead (`drain_buffered`): Zenoh's channel holds each sample in the whole buffer its link
read it into, 17 kB for a sample of 4 kB, and a full channel stops the link.
"""

from __future__ import annotations

import time
from collections import deque
from collections.abc import Callable
from typing import TypeVar

from overseer.heap_trim import trim_heap

Item = TypeVar("Item")
Copied = TypeVar("Copied")

PAUSE_SECONDS = 0.01  # what a sample may wait for its batch; at 10,000 messages a second, ~100 a batch
CHUNK = 100  # items handled between two looks at the source (0.1 s of a large fleet's first arrays)
TRIM_AFTER_BACKLOG = 20_000  # items once waiting together (~80 MB of samples): their heap is given back


def drain_paced(
    wait: Callable[[], Item | None],
    poll: Callable[[], Item | None],
    handle: Callable[[Item], None],
    stopped: Callable[[], bool],
    pause: float = PAUSE_SECONDS,
) -> None:
    """Hand every item to `handle` until `wait` returns None or `stopped()`.

    `wait` blocks for the next item (None once the source is closed); `poll` returns the next item at
    once, or None when there is none yet. A source closed by a marker it sends must say so in `stopped`
    first: `poll` may be what takes the marker.
    """
    while not stopped() and (item := wait()) is not None:
        while item is not None:
            handle(item)
            item = poll()
            if item is None and not stopped():
                time.sleep(pause)  # more may be on their way: gather them rather than wake for each
                item = poll()


def drain_buffered(
    wait: Callable[[], Item | None],
    poll: Callable[[], Item | None],
    copy: Callable[[Item], Copied],
    handle: Callable[[Copied], None],
    drop: Callable[[Copied], None],
    stopped: Callable[[], bool],
    limit: int,
    chunk: int = CHUNK,
    pause: float = PAUSE_SECONDS,
) -> None:
    """As `drain_paced`, but everything waiting at the source is copied out before each `chunk` handled.

    The copies wait in a queue of this thread's, up to `limit`; beyond it they go to `drop` at once.
    One thread both takes and handles: a second thread taking would wait for the interpreter lock after
    every item, since the source lets go of it for each one. Once a backlog of `TRIM_AFTER_BACKLOG` or
    more has been handled, the heap it took is handed back to the system.
    """
    waiting: deque[Copied] = deque()
    backlog = 0

    def take(item: Item) -> None:
        copied = copy(item)
        if len(waiting) < limit:
            waiting.append(copied)
        else:
            drop(copied)

    def sweep() -> None:
        while (item := poll()) is not None:
            take(item)

    while not stopped() and (item := wait()) is not None:
        take(item)
        while waiting:
            sweep()
            backlog = max(backlog, len(waiting))
            for _ in range(min(chunk, len(waiting))):
                handle(waiting.popleft())
            if not waiting:
                if backlog >= TRIM_AFTER_BACKLOG:
                    trim_heap()
                backlog = 0
                if not stopped():
                    time.sleep(pause)  # more may be on their way: gather them rather than wake for each
                    sweep()
