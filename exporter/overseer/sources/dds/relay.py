"""With several ingest workers, the exporter's one DDS participant a domain relays each worker its robots.

DDS cannot split a topic between readers: every reader of `rt/diagnostics` (where diagnostic_updater
publishes, whatever its node's namespace) receives every robot's samples. With a participant in each
worker, each worker received the whole fleet and dropped the others' robots: at 3,000 robots two workers
cost 1.73 times one worker's CPU a message. The exporter's process holds the one DDS source instead
(discovery, the ROS graph, which writer is which robot's) and hands each worker, down a pipe, the samples
of the robots it owns, serialized as they came, with the source's calls of the model for those robots,
in order (`outbox.py`, `relay_items.py`, the payloads through a ring both processes map,
`shared_ring.py`). The worker decodes and ingests them (`relayed.py`).

What waits for a worker that is behind is bounded by `QUEUE_LENGTH` samples; beyond it, samples are
dropped and the worker counts them. A worker started again is told first which of its robots have
writers (registered again, so that the robot cap refuses once what it refused before), then hears their
next samples. The worker's model keeps the robot cap: the source relays a refused robot's samples all the
same, and the worker drops them.
"""

from __future__ import annotations

import logging
import threading
from typing import Any

from overseer.config.dds import DdsConfig
from overseer.config.fleet import DEFAULT_NAMESPACE_DEPTH
from overseer.model.shard import Shard
from overseer.sources.dds.sink import TRANSPORT, Ingest
from overseer.sources.dds.source import DdsSource
from overseer.sources.zenoh.outbox import WorkerOutboxes
from overseer.sources.zenoh.relay_items import CALL, SAMPLE, RelayedFeed

log = logging.getLogger(__name__)

QUEUE_LENGTH = 65_536  # samples waiting for one worker (a first look of 10,000 robots is some 20,000)


class DdsRelay:
    """The exporter's DDS source, handing each of `workers` workers the robots of `shard` it owns."""

    def __init__(
        self,
        config: DdsConfig,
        shard: Shard,
        workers: int,
        namespace_depth: int = DEFAULT_NAMESPACE_DEPTH,
    ) -> None:
        """Relay the robots of `shard` to its `workers`; nothing is joined until `start`."""
        self._shard = shard
        self._workers = workers
        self._lock = threading.Lock()  # an outbox replaced, against a robot registered meanwhile
        self._feeds = WorkerOutboxes(workers, QUEUE_LENGTH, "dds-relay", self._lock)
        self._outboxes = self._feeds.outboxes
        self._registered: list[set[str]] = [set() for _ in range(workers)]  # robots with writers, by worker
        self.source = DdsSource(config, self, shard, namespace_depth)

    def attach(self, worker: int, feed: RelayedFeed) -> None:
        """Worker `worker`, started or started again, reads its batches from `feed` from now on."""
        registered = self._registered[worker]
        self._feeds.attach(
            worker, feed, lambda: [(CALL, "register", (robot, TRANSPORT)) for robot in registered]
        )

    def start(self) -> None:
        """Join the configured domains and start discovering robots (ConfigError, say, when it cannot)."""
        self.source.start()

    def stop(self) -> None:
        """Leave the domains, then close every worker's pipe."""
        self.source.stop()
        self._feeds.close()

    # The source's calls (`sink.DdsSink`), each handed to the worker of the robot it is about.

    def count_message(self, transport: str, result: str, count: int = 1) -> None:
        """Count messages in the first worker's model (they are no one robot's)."""
        self._call(0, "count_message", transport, result, count)

    def count_source_error(self, transport: str, reason: str) -> None:
        """Count a transport's failure in the first worker's model."""
        self._call(0, "count_source_error", transport, reason)

    def register(self, robot: str, transport: str) -> bool:
        """Register the robot in its worker; True: the worker's model keeps its cap (and drops beyond it)."""
        owner = self._owner(robot)
        with self._lock:
            self._registered[owner].add(robot)
            self._call(owner, "register", robot, transport)
        return True

    def forget_topic(self, robot: str, topic: str) -> None:
        """Forget the robot's topic in its worker."""
        self._call(self._owner(robot), "forget_topic", robot, topic)

    def forget_feed(self, robot: str, feed: str, last: bool) -> None:
        """Forget the robot's feed in its worker."""
        self._call(self._owner(robot), "forget_feed", robot, feed, last)

    def publisher_left(self, robot: str) -> None:
        """Mark the robot down in its worker."""
        owner = self._owner(robot)
        with self._lock:
            self._registered[owner].discard(robot)
            self._call(owner, "publisher_left", robot)

    def ingest(self, robot: str, topic: str, feed: str) -> Ingest:
        """Send the writer's samples as they are to the worker of `robot`."""
        owner, key = self._owner(robot), (robot, topic, feed)
        outboxes = self._outboxes
        # A writer whose lease ran out comes back with the same GUID: its feed is followed again.
        self._call(owner, "followed", robot, topic, feed)

        def relay(payload: bytes) -> None:
            outbox = outboxes[owner]
            if outbox is not None:
                outbox.put((SAMPLE, key, None, payload))

        return relay

    def released(self, robot: str, topic: str, feed: str) -> None:
        """Tell the robot's worker it may let go of the writer's ingest."""
        self._call(self._owner(robot), "released", robot, topic, feed)

    def _owner(self, robot: str) -> int:
        # The source hands on only the robots its shard owns, so one of its workers owns each.
        owner = self._shard.worker_of(robot, self._workers)
        return 0 if owner is None else owner

    def _call(self, worker: int, method: str, *arguments: Any) -> None:
        outbox = self._outboxes[worker]
        if outbox is not None:
            outbox.put((CALL, method, arguments))
