"""The paced drain: every sample handled in order, one wake-up for many while they stream, none when idle.

The buffered drain also empties the source before each share of the work, into a queue of its own.
"""

from __future__ import annotations

import queue
import threading
import time

import pytest

from overseer.sources import paced_drain
from overseer.sources.paced_drain import drain_buffered, drain_paced
from overseer.sources.zenoh.sequence_gaps import SequenceGaps

STREAM_ITEMS = 300
STREAM_GAP_SECONDS = 0.001
PUBLISHER = b"publisher"


class CountedQueue:
    """A queue whose blocking and non-blocking reads are counted; closed as the exporter's is."""

    def __init__(self) -> None:
        self.items: queue.SimpleQueue[int | None] = queue.SimpleQueue()
        self.closed = threading.Event()
        self.waits = 0
        self.polls = 0

    def close(self) -> None:
        """Say it is closed, then wake a drain blocked on it."""
        self.closed.set()
        self.items.put(None)

    def wait(self) -> int | None:
        self.waits += 1
        return self.items.get()

    def poll(self) -> int | None:
        self.polls += 1
        try:
            return self.items.get_nowait()
        except queue.Empty:
            return None


def drained(source: CountedQueue) -> tuple[list[int], threading.Thread]:
    handled: list[int] = []
    arguments = (source.wait, source.poll, handled.append, source.closed.is_set)
    thread = threading.Thread(target=drain_paced, args=arguments)
    thread.start()
    return handled, thread


def test_every_item_is_handled_in_order_and_the_drain_ends_when_it_is_stopped() -> None:
    source = CountedQueue()
    for item in range(1000):
        source.items.put(item)
    handled, thread = drained(source)
    deadline = time.monotonic() + 10
    while len(handled) < 1000 and time.monotonic() < deadline:
        time.sleep(0.01)
    source.close()
    thread.join(timeout=10)
    assert not thread.is_alive()
    assert handled == list(range(1000))


def test_a_stream_of_items_wakes_the_drain_once_a_batch_not_once_an_item() -> None:
    source = CountedQueue()
    handled, thread = drained(source)
    for item in range(STREAM_ITEMS):
        source.items.put(item)
        time.sleep(STREAM_GAP_SECONDS)
    source.close()
    thread.join(timeout=10)
    assert handled == list(range(STREAM_ITEMS))
    # A sleep of 1 ms takes longer on a loaded machine, so the batches may be smaller, never single items.
    assert source.waits <= STREAM_ITEMS / 4, f"{source.waits} blocking waits for {STREAM_ITEMS} items"


def test_an_idle_drain_blocks_instead_of_polling() -> None:
    source = CountedQueue()
    handled, thread = drained(source)
    source.items.put(1)
    time.sleep(0.5)  # 50 pauses' worth: a drain that kept polling would have polled about 50 times
    polls_while_idle = source.polls
    source.close()
    thread.join(timeout=10)
    assert handled == [1]
    assert polls_while_idle <= 2
    assert source.waits == 2  # the first item, then the close


def test_a_stopped_drain_ends_though_items_keep_coming() -> None:
    source = CountedQueue()
    handled, thread = drained(source)
    for item in range(50):
        source.items.put(item)
    time.sleep(0.1)
    source.closed.set()  # stopped, though nothing wakes a blocked drain
    for item in range(50, 100):
        source.items.put(item)
        time.sleep(STREAM_GAP_SECONDS)
    thread.join(timeout=10)
    assert not thread.is_alive()
    assert handled[:50] == list(range(50))
    assert len(handled) < 100


def buffered(
    source: CountedQueue, limit: int, chunk: int, gaps: SequenceGaps | None = None
) -> tuple[list[tuple[int, int]], list[list[int]]]:
    """Drain `source` buffered until it is closed: (each item handled, the source's size then), drops.

    With `gaps`, the items are one publisher's numbers: handled ones go through `gaps.missed`, and
    dropped ones are told to `gaps.heard`, as the Zenoh ingest does.
    """
    handled: list[tuple[int, int]] = []
    dropped: list[list[int]] = []

    def handle(item: int) -> None:
        handled.append((item, source.items.qsize()))
        if gaps is not None:
            gaps.missed(PUBLISHER, item)

    def drop(notes: list[int]) -> None:
        dropped.append(notes)
        if gaps is not None:
            for number in notes:
                gaps.heard(PUBLISHER, number)

    copy, note = (lambda item: item), (lambda item: item)
    arguments = (source.wait, source.poll, copy, handle, note, drop, source.closed.is_set, limit, chunk)
    thread = threading.Thread(target=drain_buffered, args=arguments)
    thread.start()
    deadline = time.monotonic() + 10
    while source.items.qsize() and time.monotonic() < deadline:
        time.sleep(0.01)
    time.sleep(0.2)  # the last share handled
    source.close()
    thread.join(timeout=10)
    assert not thread.is_alive()
    return handled, dropped


def test_the_buffered_drain_empties_the_source_before_each_share_of_the_work_and_keeps_the_order() -> None:
    source = source_with(CountedQueue(), *range(250))
    handled, dropped = buffered(source, limit=1000, chunk=100)
    assert [item for item, _ in handled] == list(range(250))
    assert dropped == []
    assert {waiting for _, waiting in handled} == {0}  # nothing left at the source while one was handled


def test_the_buffered_drain_drops_what_its_queue_cannot_hold_and_hands_on_the_rest() -> None:
    source = source_with(CountedQueue(), *range(250))
    handled, dropped = buffered(source, limit=100, chunk=10)
    assert [item for item, _ in handled] == list(range(100))
    assert dropped == [list(range(100, 250))]  # one run of drops, told once


def test_what_the_buffered_drain_dropped_is_told_in_its_place_so_it_is_not_counted_lost_as_well() -> None:
    gaps = SequenceGaps()
    source = source_with(CountedQueue(), *range(1, 6))  # a publisher's first numbers, the ingest behind
    handled, dropped = buffered(source, limit=3, chunk=2, gaps=gaps)
    assert dropped == [[4, 5]]
    handled_after, _ = buffered(source_with(CountedQueue(), 6), limit=3, chunk=2, gaps=gaps)
    assert [item for item, _ in handled + handled_after] == [1, 2, 3, 6]
    assert gaps.lost(PUBLISHER) == 0


def source_with(source: CountedQueue, *items: int) -> CountedQueue:
    """`source` holding `items`."""
    for item in items:
        source.items.put(item)
    return source


def test_a_stopped_buffered_drain_leaves_its_backlog() -> None:
    source = source_with(CountedQueue(), *range(1000))
    handled: list[int] = []

    def slow(item: int) -> None:
        handled.append(item)
        time.sleep(0.01)

    arguments = (source.wait, source.poll, int, slow, int, print, source.closed.is_set, 10_000, 100)
    thread = threading.Thread(target=drain_buffered, args=arguments)
    thread.start()
    time.sleep(0.2)
    source.closed.set()  # stopped, with hundreds of copies still waiting
    thread.join(timeout=10)
    assert not thread.is_alive()
    assert 0 < len(handled) < 200


@pytest.mark.parametrize(("waiting", "trims"), [(60, 1), (40, 0)])
def test_the_buffered_drain_gives_a_large_backlogs_heap_back_once_it_is_handled(
    monkeypatch: pytest.MonkeyPatch, waiting: int, trims: int
) -> None:
    trims_seen: list[None] = []
    source = source_with(CountedQueue(), *range(waiting))

    def trim() -> bool:
        trims_seen.append(None)
        return True

    monkeypatch.setattr(paced_drain, "TRIM_AFTER_BACKLOG", 50)
    monkeypatch.setattr(paced_drain, "trim_heap", trim)
    handled, _ = buffered(source, limit=1000, chunk=10)
    assert len(handled) == waiting
    assert len(trims_seen) == trims  # once the backlog was handled, not after each share of it
