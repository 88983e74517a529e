"""What the exporter's Zenoh session has heard and its ingest has not taken yet: a bounded queue of items.

With several ingest workers, the session's drain only copies each sample out of Zenoh, finds its worker
and queues it here; a thread of the outbox sends the items down the worker's pipe in batches, in order,
their payloads through shared memory (`relay.py`). Zenoh's own channel therefore stays short even while a
worker is seconds behind (a large fleet's first look). That matters twice: a sample waiting in Zenoh's
channel holds the whole buffer its link read it into (17 kB a sample of 4 kB, measured at 10,000 robots:
1 GB for a backlog of 65,536), and a full channel stops Zenoh from reading the link, so the router drops
what it cannot send.

Beyond `limit` samples, a sample is dropped; the drops are queued as one item, in their place, with the
highest number dropped of each publisher, so that the ingest counts them dropped, and not lost as well.
Once a large backlog has drained, the heap it took is handed back to the system (`heap_trim.py`).
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable, Iterable
from multiprocessing.connection import Connection

from overseer.heap_trim import TRIM_AFTER_BACKLOG, trim_heap
from overseer.sources.zenoh.keys import attachment_fields
from overseer.sources.zenoh.relay_items import DROPPED, SAMPLE, Item, RelayedFeed, encode_batch

log = logging.getLogger(__name__)

MAX_TOKENS = 200_000  # tokens that may wait beyond the samples (a fleet's, two a robot), publishers noted
MAX_BATCH = 2_000  # items a batch: a receiver far behind gets its backlog in pieces, not one huge pickle
# What an item may wait for its batch. Each batch wakes this thread and the worker's reader, and each
# waits for its process's interpreter lock: with four workers at 3,000 robots, batches every 10 ms cost
# 77-83 µs of CPU a message in all, every 50 ms 58-61 µs (runs alternating), for 20-40 ms more latency.
BATCH_PAUSE_SECONDS = 0.05

Deliver = Callable[[list[Item]], bool]  # hands one batch on; False once its receiver is gone


class Outbox:
    """Items waiting for one receiver, and the thread that hands them to `deliver` in batches."""

    def __init__(self, limit: int, deliver: Deliver, name: str) -> None:
        """Hold up to `limit` samples for `deliver`; `start` starts handing them on."""
        self._limit = limit
        self._deliver = deliver
        self._name = name
        self._items: list[Item] = []
        self._samples = 0  # of `_items`
        self._backlog = 0  # the most samples waiting together since the queue was last empty
        self._dropped = 0
        self._tokens_dropped = 0
        self._heard: dict[bytes, int] = {}  # the highest number dropped of each publisher
        self._ready = threading.Condition()
        self._closed = False

    def start(self) -> None:
        """Start handing the items on, in a thread of the outbox's own."""
        threading.Thread(target=self._send_loop, name=self._name, daemon=True).start()

    def put(self, item: Item, attachment: bytes | None = None) -> None:
        """Queue `item`; a sample beyond the limit is dropped, counted with its `attachment`'s number."""
        is_sample = item[0] == SAMPLE
        with self._ready:
            if self._closed:
                return
            if not is_sample and len(self._items) >= self._limit + MAX_TOKENS:
                if not self._tokens_dropped:  # a flood of tokens to a receiver that is stuck
                    log.warning("an ingest worker is too far behind: tokens or calls dropped from its queue")
                self._tokens_dropped += 1
                return
            if is_sample and self._samples >= self._limit:
                self._dropped += 1
                gid, sequence = attachment_fields(attachment)
                if gid is not None and sequence is not None and len(self._heard) < MAX_TOKENS:
                    self._heard[gid] = max(sequence, self._heard.get(gid, sequence))
                return
            self._take_drops()  # they came before this item: the receiver takes them in the same order
            self._items.append(item)
            self._samples += is_sample
            self._backlog = max(self._backlog, self._samples)
            self._ready.notify()

    def close(self) -> None:
        """Hand nothing more on."""
        with self._ready:
            self._closed = True
            self._ready.notify()

    def _take_drops(self) -> None:
        """Queue what was dropped since the last item as one item, under `_ready`."""
        if self._dropped:
            self._items.append((DROPPED, self._dropped, list(self._heard.items())))
            self._dropped, self._heard = 0, {}

    def _send_loop(self) -> None:
        while True:
            with self._ready:
                while not self._items and not self._dropped and not self._closed:
                    self._ready.wait()
                if self._closed:
                    return
                if len(self._items) <= MAX_BATCH:
                    self._take_drops()  # after every item that waited: they were dropped after those
                batch = self._items[:MAX_BATCH]
                del self._items[:MAX_BATCH]
                self._samples -= sum(1 for item in batch if item[0] == SAMPLE)
                more = bool(self._items)
                drained = not more and self._backlog >= TRIM_AFTER_BACKLOG
                if not more:
                    self._backlog = 0
            if not self._deliver(batch):
                return
            if drained:
                trim_heap()
            if not more:
                time.sleep(BATCH_PAUSE_SECONDS)  # let the next batch gather rather than hand each alone


class WorkerOutboxes:
    """A relay's outbox and pipe for each worker: replaced when the worker starts again, closed at the end.

    `outboxes` is the one list for the relay's lifetime (an entry None while its worker has none), so a
    hot path may hold it.
    """

    def __init__(self, workers: int, limit: int, name: str, lock: threading.Lock) -> None:
        """Outboxes of `limit` samples, their threads named `name`-N; `lock` is the relay's."""
        self.outboxes: list[Outbox | None] = [None] * workers
        self._connections: list[Connection | None] = [None] * workers
        self._limit = limit
        self._name = name
        self._lock = lock

    def attach(self, worker: int, feed: RelayedFeed, first: Callable[[], Iterable[Item]]) -> None:
        """Relay to `worker` through `feed` from now on, `first()`'s items (taken under the lock) first."""
        outbox = Outbox(self._limit, _sender(feed), f"{self._name}-{worker}")
        outbox.start()
        with self._lock:
            for item in first():
                outbox.put(item)
            old, self.outboxes[worker] = self.outboxes[worker], outbox
            old_connection, self._connections[worker] = self._connections[worker], feed.connection
        _close(old, old_connection)

    def close(self) -> None:
        """Relay nothing more: close every outbox and pipe (each worker reads its pipe to the end)."""
        with self._lock:
            outboxes, connections = list(self.outboxes), list(self._connections)
            for worker in range(len(self.outboxes)):
                self.outboxes[worker] = self._connections[worker] = None
        for outbox, connection in zip(outboxes, connections, strict=True):
            _close(outbox, connection)


def _sender(feed: RelayedFeed) -> Deliver:
    """Sends a batch down a worker's pipe and ring; False once the worker is gone (the pool restarts it)."""
    connection, ring = feed.connection, feed.ring

    def send(batch: list[Item]) -> bool:
        try:
            connection.send_bytes(encode_batch(batch, ring))
        except (OSError, ValueError):
            log.debug("an ingest worker's pipe closed while samples were relayed to it")
            return False
        return True

    return send


def _close(outbox: Outbox | None, connection: Connection | None) -> None:
    """Stop relaying to a worker, and close its pipe."""
    if outbox is not None:
        outbox.close()
    if connection is not None:
        connection.close()
