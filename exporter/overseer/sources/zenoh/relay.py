"""With several ingest workers, the exporter's one Zenoh session relays each worker its own robots' samples.

Zenoh cannot split a fleet by a hash of the robot's name, so a worker with a session of its own either
hears every robot (and the fleet's samples cross into every worker: the cost multiplied by the workers)
or subscribes to each of its robots' topics (a declaration costs the session and the router more the
more there are: about 1 ms each at 4,000, so seconds of CPU as a large fleet is first heard). The
exporter's process holds the one session instead, with the wildcard subscriptions of one worker, and
hands each sample to the worker that owns its robot through a pipe, in batches (`outbox.py`,
`relay_items.py`), the payloads through a ring of memory both processes map (`shared_ring.py`):
the key tells the robot of a namespaced topic, the publisher's GID, from its liveliness token, that of
the un-namespaced `/diagnostics`. Every worker gets every token, and a worker started again gets the
tokens alive then, before any sample. Samples whose robot is not known yet go to every worker, which
holds them until the token says whose they are, as one session's ingest does.

What waits for a worker that is behind is bounded by `zenoh.queue_length` samples; beyond it, samples are
dropped and the worker counts them (and does not count them lost as well).
"""

from __future__ import annotations

import logging
import threading

from overseer.config.fleet import DEFAULT_NAMESPACE_DEPTH
from overseer.config.zenoh import ZenohConfig
from overseer.model.shard import Shard
from overseer.sources.robot_naming import RobotNaming
from overseer.sources.zenoh.keys import RejectedKey, attachment_gid, parse_data_key
from overseer.sources.zenoh.outbox import WorkerOutboxes
from overseer.sources.zenoh.receiver import ZenohReceiver
from overseer.sources.zenoh.relay_items import ERROR, SAMPLE, TOKEN, RelayedFeed
from overseer.sources.zenoh.tokens import token_subject

log = logging.getLogger(__name__)

MAX_ROUTES = 100_000  # keys remembered with their worker (bounded against key floods)
MAX_LIVE_TOKENS = 200_000  # tokens remembered for a worker that starts again, and GIDs with their robot
_FOREIGN = -1  # a key of a robot another shard follows
_BY_PUBLISHER = -2  # an un-namespaced topic: the publisher's GID says whose


class ZenohRelay:
    """One Zenoh session of the exporter's process, relaying each of `workers` workers its robots' samples."""

    def __init__(
        self,
        config: ZenohConfig,
        shard: Shard,
        workers: int,
        namespace_depth: int = DEFAULT_NAMESPACE_DEPTH,
    ) -> None:
        """Relay the robots of `shard` to its `workers`; ConfigError at once if the session is unusable."""
        self._config = config
        self._shard = shard
        self._workers = workers
        self._naming = RobotNaming(config.unnamespaced_robot, config.robot_name is not None, namespace_depth)
        self._routes: dict[str, int] = {}
        self._publishers: dict[bytes, str] = {}  # GID → robot, of the tokens alive
        self._live: dict[str, None] = {}  # the tokens alive, in the order they came
        self._lock = threading.Lock()
        self._feeds = WorkerOutboxes(workers, config.queue_length, "zenoh-relay", self._lock)
        self._outboxes = self._feeds.outboxes
        self.receiver = ZenohReceiver(config, self.on_sample, self.on_token, self._unreachable, lambda: None)

    def attach(self, worker: int, feed: RelayedFeed) -> None:
        """Worker `worker`, started or started again, reads its batches from `feed` from now on."""
        self._feeds.attach(worker, feed, lambda: [(TOKEN, key, True) for key in self._live])

    def start(self) -> None:
        """Open the session in the background."""
        self.receiver.start()

    def stop(self) -> None:
        """Close the session, then every worker's pipe."""
        self.receiver.stop()
        self._feeds.close()

    def on_sample(self, key: str, attachment: bytes | None, payload: bytes) -> None:
        """Hand one sample to the worker of its robot (to every worker while its robot is not known)."""
        route = self._routes.get(key)
        if route is None:
            route = self._route_of(key)
        if route == _FOREIGN:
            return
        if route == _BY_PUBLISHER:
            gid = attachment_gid(attachment)
            robot = self._publishers.get(gid) if gid else self._naming.unnamespaced_robot
            if robot is None:  # its token has not come (yet): every worker holds it until it does
                for outbox in self._outboxes:
                    if outbox is not None:
                        outbox.put((SAMPLE, key, attachment, payload), attachment)
                return
            owner = self._shard.worker_of(robot, self._workers)
            if owner is None:
                return
            route = owner
        outbox = self._outboxes[route]
        if outbox is not None:
            outbox.put((SAMPLE, key, attachment, payload), attachment)

    def _route_of(self, key: str) -> int:
        """The worker a key's samples go to, `_FOREIGN`, or `_BY_PUBLISHER`; remembered, up to a bound."""
        try:
            parsed = parse_data_key(key, self._config.domain)
        except RejectedKey:
            return 0  # the first worker counts what is wrong with it; not remembered (a flood of keys)
        robot = self._naming.of_topic(parsed.namespace)
        if robot is None:
            route = _BY_PUBLISHER
        else:
            owner = self._shard.worker_of(robot, self._workers)
            route = _FOREIGN if owner is None else owner
        if len(self._routes) < MAX_ROUTES:
            self._routes[key] = route
        return route

    def on_token(self, key: str, alive: bool) -> None:
        """Hand one publisher token to every worker, and remember it while it is alive."""
        subject = token_subject(key, self._config, self._naming)
        if subject is None:
            return
        with self._lock:
            if alive:
                if len(self._live) < MAX_LIVE_TOKENS:
                    self._live[key] = None
                    if subject.gid and subject.robot is not None:
                        self._publishers[subject.gid] = subject.robot
            else:
                self._live.pop(key, None)
                self._publishers.pop(subject.gid, None)
            for outbox in self._outboxes:
                if outbox is not None:
                    outbox.put((TOKEN, key, alive))

    def _unreachable(self) -> None:
        outbox = self._outboxes[0]
        if outbox is not None:
            outbox.put((ERROR, "router_unreachable"))
