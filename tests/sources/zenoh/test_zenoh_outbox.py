"""The queue between the Zenoh session and the ingest: order, drops in their place, the heap given back."""

from __future__ import annotations

import threading
import time

import pytest

from overseer.simulator.zenoh_publisher import attachment
from overseer.sources.zenoh import outbox as outbox_module
from overseer.sources.zenoh.outbox import Outbox
from overseer.sources.zenoh.relay_items import DROPPED, SAMPLE, TOKEN, Item
from testbed.processes import wait_for

GID = bytes(range(16))


class Receiver:
    """Takes the outbox's batches, and says when it has taken `expected` items."""

    def __init__(self) -> None:
        """Nothing taken yet."""
        self.items: list[Item] = []
        self.batches = 0
        self.lock = threading.Lock()

    def __call__(self, batch: list[Item]) -> bool:
        """One batch handed on."""
        with self.lock:
            self.items.extend(batch)
            self.batches += 1
        return True


def sample(number: int) -> tuple[Item, bytes]:
    """The item and attachment of a numbered sample of one publisher."""
    numbered = attachment(number, 0, GID)
    return (SAMPLE, "0/robot/diagnostics", numbered, b"payload"), numbered


def test_items_are_handed_on_in_order_and_the_dropped_in_their_place_with_the_highest_number() -> None:
    receiver = Receiver()
    outbox = Outbox(3, receiver, "test-outbox")
    for number in range(1, 6):  # nothing takes them yet: 3 wait, 2 are dropped
        outbox.put(*sample(number))
    outbox.put((TOKEN, "token", True))
    outbox.start()
    wait_for(lambda: len(receiver.items) == 5, 5, message="the items handed on")
    outbox.close()
    kinds = [item[0] for item in receiver.items]
    assert kinds == [SAMPLE, SAMPLE, SAMPLE, DROPPED, TOKEN]
    assert receiver.items[3] == (DROPPED, 2, [(GID, 5)])
    assert [item[2] for item in receiver.items[:3]] == [sample(n)[1] for n in (1, 2, 3)]


@pytest.mark.parametrize(("waiting", "trims"), [(60, 1), (40, 0)])
def test_the_heap_is_given_back_once_a_large_backlog_has_drained(
    monkeypatch: pytest.MonkeyPatch, waiting: int, trims: int
) -> None:
    trimmed: list[int] = []
    receiver = Receiver()
    monkeypatch.setattr(outbox_module, "TRIM_AFTER_BACKLOG", 50)
    monkeypatch.setattr(outbox_module, "MAX_BATCH", 10)

    def trim() -> bool:
        trimmed.append(len(receiver.items))
        return True

    monkeypatch.setattr(outbox_module, "trim_heap", trim)
    outbox = Outbox(1000, receiver, "test-outbox")
    for number in range(waiting):
        outbox.put(*sample(number))
    outbox.start()
    wait_for(lambda: len(receiver.items) == waiting, 5, message="the backlog handed on")
    for number in range(waiting, waiting + 20):  # a small backlog after it: no trim of its own
        outbox.put(*sample(number))
    wait_for(lambda: len(receiver.items) == waiting + 20, 5, message="the rest handed on")
    outbox.close()
    assert receiver.batches >= waiting // 10
    assert trimmed == [waiting] * trims  # once, after the last of the backlog was handed on


def test_a_trickle_of_samples_is_handed_on_in_batches_a_pause_apart() -> None:
    # A worker's share of a fleet: each batch wakes the outbox's thread and the worker's reader, and
    # each of them waits for its process's interpreter lock. Batches 10 ms apart cost a third more CPU.
    receiver = Receiver()
    outbox = Outbox(1000, receiver, "test-outbox")
    outbox.start()
    trickle = 40
    started = time.monotonic()
    for number in range(trickle):  # a sample every 5 ms or so
        outbox.put(*sample(number))
        time.sleep(0.005)
    took = time.monotonic() - started
    wait_for(lambda: len(receiver.items) == trickle, 5, message="the trickle handed on")
    outbox.close()
    assert receiver.batches <= took / 0.05 + 2, (receiver.batches, took)  # the first sample goes alone
