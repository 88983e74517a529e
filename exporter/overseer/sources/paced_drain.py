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
from typing import Generic, TypeVar

from overseer.heap_trim import TRIM_AFTER_BACKLOG, trim_heap

Item = TypeVar("Item")
Copied = TypeVar("Copied")
Note = TypeVar("Note")

PAUSE_SECONDS = 0.01  # what a sample may wait for its batch; at 10,000 messages a second, ~100 a batch
CHUNK = 100  # items handled between two looks at the source (0.1 s of a large fleet's first arrays)
SWEEP_LIMIT = 5_000  # items taken from the source at most between two shares of the work


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


class _Dropped(Generic[Note]):
    """Where items were dropped in the queue, with a note of each: handled in their place, in order."""

    __slots__ = ("notes",)

    def __init__(self, note: Note) -> None:
        self.notes = [note]


def drain_buffered(
    wait: Callable[[], Item | None],
    poll: Callable[[], Item | None],
    copy: Callable[[Item], Copied | None],
    handle: Callable[[Copied], None],
    note: Callable[[Item], Note],
    drop: Callable[[list[Note]], None],
    stopped: Callable[[], bool],
    limit: int,
    chunk: int = CHUNK,
    pause: float = PAUSE_SECONDS,
) -> None:
    """As `drain_paced`, but what waits at the source is copied out (None: left out) before each `chunk`.

    The copies wait in a queue of this thread's, up to `limit`; an item beyond it is not copied but noted,
    and `drop` is given the notes of a run of drops where they came, after the copies before them (so
    that a publisher's numbers are told in order). One thread both takes and handles: a second thread
    taking would wait for the interpreter lock after every item, since the source lets go of it for
    each. Once a backlog of `TRIM_AFTER_BACKLOG` or more has been handled, its heap is handed back.
    """
    waiting: deque[Copied | _Dropped[Note]] = deque()
    backlog = 0

    def take(item: Item) -> None:
        if len(waiting) < limit:
            copied = copy(item)
            if copied is not None:
                waiting.append(copied)
        elif isinstance(last := waiting[-1], _Dropped):
            last.notes.append(note(item))
        else:
            waiting.append(_Dropped(note(item)))

    def sweep() -> None:  # a bounded share: a source that never empties must not starve the handling
        for _ in range(SWEEP_LIMIT):
            item = poll()
            if item is None:
                return
            take(item)

    while not stopped() and (item := wait()) is not None:
        take(item)
        while waiting and not stopped():
            sweep()
            backlog = max(backlog, len(waiting))
            for _ in range(min(chunk, len(waiting))):
                entry = waiting.popleft()
                if isinstance(entry, _Dropped):
                    drop(entry.notes)
                else:
                    handle(entry)
            if not waiting:
                if backlog >= TRIM_AFTER_BACKLOG:
                    trim_heap()
                backlog = 0
                if not stopped():
                    time.sleep(pause)  # more may be on their way: gather them rather than wake for each
                    sweep()
