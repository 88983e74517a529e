"""What the exporter's relays send an ingest worker: batches of samples, tokens, calls and counts, in order.

A batch is a pickled list of items, each a tuple whose first element says what it is. With a ring of
shared memory (`shared_ring.py`), the samples' payloads go through the ring and the pickle carries
where they start and each one's length in place of its payload. The pipe joins two processes of one
exporter, so what it carries is trusted as the exporter's own objects are.
"""

from __future__ import annotations

import pickle
from dataclasses import dataclass
from multiprocessing.connection import Connection
from typing import Any

from overseer.sources.zenoh.shared_ring import SharedRing

SAMPLE = 0  # (SAMPLE, key, attachment or None, payload)
TOKEN = 1  # (TOKEN, key, alive)
DROPPED = 2  # (DROPPED, count, [(publisher GID, highest number), ...]): dropped by a full outbox
ERROR = 3  # (ERROR, reason): an error of the exporter's session, for the worker that counts them
CALL = 4  # (CALL, method, arguments): a call of the worker's model by the exporter's DDS source
# From the DDS relay (`dds/relay.py`) a SAMPLE's key is (robot, topic, feed), with no attachment.

Item = tuple[Any, ...]  # one of the five above, its kind first


@dataclass(frozen=True)
class RelayedFeed:
    """What a worker reads the relay's batches from: the pipe, and the ring their payloads come through."""

    connection: Connection
    ring: SharedRing | None = None


def encode_batch(items: list[Item], ring: SharedRing | None = None) -> bytes:
    """One batch as the bytes sent down the pipe, its payloads placed in `ring` when they fit there."""
    if ring is None:
        return pickle.dumps(items, protocol=pickle.HIGHEST_PROTOCOL)
    payloads = [item[3] for item in items if item[0] == SAMPLE]
    if payloads:
        placed = ring.place(payloads)
        if placed is not None:
            lengths = [(SAMPLE, *item[1:3], len(item[3])) if item[0] == SAMPLE else item for item in items]
            return pickle.dumps((*placed, lengths), protocol=pickle.HIGHEST_PROTOCOL)
    return pickle.dumps(items, protocol=pickle.HIGHEST_PROTOCOL)


def decode_batch(data: bytes, ring: SharedRing | None = None) -> list[Item]:
    """The items of one batch received from the pipe, their payloads taken out of `ring` if there."""
    decoded = pickle.loads(data)  # written by this exporter's own process
    if isinstance(decoded, list):
        return decoded
    if ring is None:
        raise ValueError("a batch whose payloads are in shared memory, and no ring to read them from")
    start, end, items = decoded
    payloads = iter(ring.take(start, [item[3] for item in items if item[0] == SAMPLE]))
    ring.release(end)
    return [(SAMPLE, *item[1:3], next(payloads)) if item[0] == SAMPLE else item for item in items]
