"""The ring of shared memory the relayed samples' payloads cross in: nothing unread overwritten, nothing lost.

A batch whose payloads do not fit goes down the pipe whole; a worker in another process reads what the
exporter's process placed, through the memory file passed to it as a worker's arguments are.
"""

from __future__ import annotations

import pickle
from multiprocessing.connection import Connection, Pipe

import pytest

from overseer.fleet.workers.launch import start_child
from overseer.sources.zenoh.relay_items import (
    DROPPED,
    SAMPLE,
    TOKEN,
    Item,
    RelayedFeed,
    decode_batch,
    encode_batch,
)
from overseer.sources.zenoh.shared_ring import SharedRing

RING_BYTES = 1000
TIMEOUT_SECONDS = 30.0


def samples(count: int, size: int, first: int = 0) -> list[Item]:
    """`count` samples of `size`-byte payloads, each payload its own (numbered) bytes."""
    return [
        (SAMPLE, f"0/robot{n}/diagnostics", None if n % 2 else bytes([n % 256]) * 24, bytes([n % 256]) * size)
        for n in range(first, first + count)
    ]


def test_a_batch_crosses_in_the_ring_and_the_pipe_carries_only_its_lengths() -> None:
    ring = SharedRing.create(RING_BYTES)
    batch = [(TOKEN, "token", True), *samples(3, 200), (DROPPED, 2, [(b"gid", 7)])]
    data = encode_batch(batch, ring)
    assert len(data) < 300  # the 600 bytes of payloads are not in it
    assert decode_batch(data, ring) == batch


def test_what_the_worker_has_not_taken_is_never_written_over() -> None:
    ring = SharedRing.create(RING_BYTES)
    first = encode_batch(samples(4, 200), ring)  # 800 of 1000 bytes
    second = samples(2, 200, first=4)
    assert pickle.loads(encode_batch(second, ring)) == second  # no room: down the pipe whole
    assert decode_batch(first, ring) == samples(4, 200)  # taken: the ring is free again
    third = encode_batch(second, ring)  # would cross the ring's end: placed at its start instead
    assert not isinstance(pickle.loads(third), list)
    assert decode_batch(third, ring) == second


def test_a_batch_that_would_wrap_waits_for_the_worker_to_have_read_the_ring_start() -> None:
    ring = SharedRing.create(RING_BYTES)
    first, second = encode_batch(samples(2, 300), ring), encode_batch(samples(2, 200, first=2), ring)
    assert decode_batch(first, ring) == samples(2, 300)  # taken: 600 of the ring's first 1000 bytes free
    exact = samples(2, 500, first=4)  # the whole ring, from its start: the second batch is not read yet
    assert isinstance(pickle.loads(encode_batch(exact, ring)), list)
    assert decode_batch(second, ring) == samples(2, 200, first=2)
    placed = encode_batch(exact, ring)  # all read: the whole ring is free
    assert not isinstance(pickle.loads(placed), list)
    assert decode_batch(placed, ring) == exact


def test_a_batch_without_samples_leaves_the_ring_alone() -> None:
    ring = SharedRing.create(RING_BYTES)
    batch = [(TOKEN, "token", False), (DROPPED, 1, [])]
    assert pickle.loads(encode_batch(batch, ring)) == batch
    assert ring._written == 0


def test_a_batch_larger_than_the_ring_goes_down_the_pipe_and_a_pipe_batch_needs_no_ring() -> None:
    ring = SharedRing.create(RING_BYTES)
    batch = samples(1, RING_BYTES + 1)
    data = encode_batch(batch, ring)
    assert decode_batch(data, None) == batch
    shared = encode_batch(samples(1, 10), ring)
    with pytest.raises(ValueError, match="no ring"):
        decode_batch(shared, None)


def read_in_a_worker(feed: RelayedFeed, answers: Connection) -> None:
    """In a child process, as a worker reads the relay: decode each batch, and send its items back."""
    while (data := feed.connection.recv_bytes()) != b"end":
        answers.send(decode_batch(data, feed.ring))


def test_a_worker_process_takes_the_payloads_the_exporters_process_placed() -> None:
    ring = SharedRing.create(4 * RING_BYTES)
    reader, writer = Pipe(duplex=False)
    answers, child_answers = Pipe(duplex=False)
    child = start_child(read_in_a_worker, (RelayedFeed(reader, ring), child_answers))
    reader.close()
    child_answers.close()
    try:
        for turn in range(20):  # 900 bytes a batch: the ring goes round four times
            batch = samples(3, 300, first=10 * turn)
            data = encode_batch(batch, ring)
            assert not isinstance(pickle.loads(data), list)  # in the ring: the worker released the last
            writer.send_bytes(data)
            assert answers.poll(TIMEOUT_SECONDS), "the worker never answered"
            assert answers.recv() == batch
        writer.send_bytes(b"end")
        child.join(TIMEOUT_SECONDS)
        assert child.exitcode == 0
    finally:
        child.kill()
