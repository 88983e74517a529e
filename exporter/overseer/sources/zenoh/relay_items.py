"""What the exporter's Zenoh relay sends an ingest worker: batches of samples, tokens and counts, in order.

A batch is a pickled list of items, each a tuple whose first element says what it is. The pipe joins two
processes of one exporter, so what it carries is trusted as the exporter's own objects are.
"""

from __future__ import annotations

import pickle
from typing import Any

SAMPLE = 0  # (SAMPLE, key, attachment or None, payload)
TOKEN = 1  # (TOKEN, key, alive)
DROPPED = 2  # (DROPPED, count, [(publisher GID, highest number), ...]): dropped by a full outbox
ERROR = 3  # (ERROR, reason): an error of the exporter's session, for the worker that counts them

Item = tuple[Any, ...]  # one of the four above, its kind first


def encode_batch(items: list[Item]) -> bytes:
    """One batch as the bytes sent down the pipe."""
    return pickle.dumps(items, protocol=pickle.HIGHEST_PROTOCOL)


def decode_batch(data: bytes) -> list[Item]:
    """The items of one batch received from the pipe."""
    items: list[Item] = pickle.loads(data)  # written by this exporter's own process
    return items
