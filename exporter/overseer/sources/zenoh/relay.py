"""With several ingest workers, the exporter's one Zenoh session relays each worker its own robots' samples.

Zenoh cannot split a fleet by a hash of the robot's name, so a worker with a session of its own either
hears every robot (and the fleet's samples cross into every worker: the cost multiplied by the workers)
or subscribes to each of its robots' topics (a declaration costs the session and the router more the
more there are: about 1 ms each at 4,000, so seconds of CPU as a large fleet is first heard). The
exporter's process holds the one session instead, with the wildcard subscriptions of one worker, and
hands each sample to the worker that owns its robot through a pipe, in batches (`relay_items.py`):
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
import time
from multiprocessing.connection import Connection

from overseer.config.fleet import DEFAULT_NAMESPACE_DEPTH
from overseer.config.zenoh import ZenohConfig
from overseer.model.shard import Shard
from overseer.sources.robot_naming import RobotNaming
from overseer.sources.zenoh.keys import RejectedKey, attachment_fields, attachment_gid, parse_data_key
from overseer.sources.zenoh.receiver import ZenohReceiver
from overseer.sources.zenoh.relay_items import DROPPED, ERROR, SAMPLE, TOKEN, Item, encode_batch
from overseer.sources.zenoh.tokens import token_subject

log = logging.getLogger(__name__)

PAUSE_SECONDS = 0.01  # what a sample may wait for its batch to gather: ~100 a batch at 10,000 a second
MAX_BATCH = 2_000  # items a batch: a worker far behind gets its backlog in pieces, not one huge pickle
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
        self._outboxes: list[_Outbox | None] = [None] * workers
        self._routes: dict[str, int] = {}
        self._publishers: dict[bytes, str] = {}  # GID → robot, of the tokens alive
        self._live: dict[str, None] = {}  # the tokens alive, in the order they came
        self._lock = threading.Lock()
        self.receiver = ZenohReceiver(config, self.on_sample, self.on_token, self._unreachable, lambda: None)

    def attach(self, worker: int, connection: Connection) -> None:
        """Worker `worker`, started or started again, reads its batches from `connection` from now on."""
        outbox = _Outbox(connection, self._config.queue_length, f"zenoh-relay-{worker}")
        with self._lock:
            for key in self._live:
                outbox.put((TOKEN, key, True))
            old, self._outboxes[worker] = self._outboxes[worker], outbox
        if old is not None:
            old.close()

    def start(self) -> None:
        """Open the session in the background."""
        self.receiver.start()

    def stop(self) -> None:
        """Close the session, then every worker's pipe."""
        self.receiver.stop()
        with self._lock:
            outboxes, self._outboxes = self._outboxes, [None] * len(self._outboxes)
        for outbox in outboxes:
            if outbox is not None:
                outbox.close()

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


class _Outbox:
    """What waits for one worker, and the thread that sends it down the worker's pipe in batches."""

    def __init__(self, connection: Connection, limit: int, name: str) -> None:
        self._connection = connection
        self._limit = limit
        self._items: list[Item] = []
        self._samples = 0  # of `_items`
        self._dropped = 0
        self._tokens_dropped = 0
        self._heard: dict[bytes, int] = {}  # the highest number dropped of each publisher
        self._ready = threading.Condition()
        self._closed = False
        threading.Thread(target=self._send_loop, name=name, daemon=True).start()

    def put(self, item: Item, attachment: bytes | None = None) -> None:
        """Queue `item`; a sample beyond the limit is dropped, counted with its `attachment`'s number."""
        is_sample = item[0] == SAMPLE
        with self._ready:
            if self._closed:
                return
            if not is_sample and len(self._items) >= self._limit + MAX_LIVE_TOKENS:
                if not self._tokens_dropped:  # a flood of tokens to a worker that is stuck
                    log.warning("an ingest worker is too far behind: Zenoh tokens dropped from its queue")
                self._tokens_dropped += 1
                return
            if is_sample and self._samples >= self._limit:
                self._dropped += 1
                gid, sequence = attachment_fields(attachment)
                if gid is not None and sequence is not None and len(self._heard) < MAX_LIVE_TOKENS:
                    self._heard[gid] = max(sequence, self._heard.get(gid, sequence))
                return
            self._take_drops()  # they came before this item: the worker takes them in the same order
            self._items.append(item)
            self._samples += is_sample
            self._ready.notify()

    def _take_drops(self) -> None:
        """Queue what was dropped since the last item as one item, under `_ready`."""
        if self._dropped:
            self._items.append((DROPPED, self._dropped, list(self._heard.items())))
            self._dropped, self._heard = 0, {}

    def close(self) -> None:
        """Send nothing more, and close the pipe: the worker reads to its end."""
        with self._ready:
            self._closed = True
            self._ready.notify()
        self._connection.close()

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
            try:
                self._connection.send_bytes(encode_batch(batch))
            except (OSError, ValueError):  # the worker is gone: the pool attaches the one started again
                log.debug("an ingest worker's pipe closed while samples were relayed to it")
                return
            if not more:
                time.sleep(PAUSE_SECONDS)  # let the next batch gather rather than send each sample alone
