"""The paced drain: every sample handled in order, one wake-up for many while they stream, none when idle."""

from __future__ import annotations

import queue
import threading
import time

from overseer.sources.paced_drain import drain_paced

STREAM_ITEMS = 300
STREAM_GAP_SECONDS = 0.001


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
