"""The Zenoh transport: robots on rmw_zenoh (ROS 2 Jazzy) and robots behind zenoh-bridge-ros2dds.

One Zenoh session (a client of the configured routers by default) subscribes to every robot's
diagnostics keys with wildcards, so robots that start later, or were built against another revision of
the message (another type hash), are heard with no restart. Payloads are DDS CDR and go through the
same ingest as DDS samples. rmw_zenoh's liveliness tokens tell when a robot's diagnostics publisher
goes (process killed, link lost), and so do zenoh-bridge-ros2dds's tokens for the routes it serves:
the robot is down at once, not after `robot_timeout`.

A sample of an un-namespaced topic (diagnostic_updater publishes on `/diagnostics` whatever its node's
namespace) belongs to the robot its publisher's node names: the sample's attachment carries the
publisher's GID, and the publisher's liveliness token, whose hash that GID is, its node's namespace
(`robot_naming.py`). Each publisher is a feed of its robot.

With several ingest workers (or shards), a worker subscribes only to its own robots: it hears every
publisher's liveliness token, and for each namespaced diagnostics topic of a robot it owns declares a
subscription to that topic alone, so the router sends each worker its share and adding a worker divides
the cost instead of multiplying it. Topics without a namespace are heard by every worker (any robot may
publish there; the GID says whose). A namespaced publisher that declares no token (neither rmw_zenoh nor
the bridge) is followed with one worker only.
"""

from __future__ import annotations

import contextlib
import logging
import queue
import threading
import time
from dataclasses import dataclass, field
from typing import Any

import zenoh
from zenoh.handlers import Callback, FifoChannel

from overseer.codec import DecodeError, cdr
from overseer.config.fleet import DEFAULT_NAMESPACE_DEPTH
from overseer.config.zenoh import ZenohConfig
from overseer.ingest.payload import PayloadIngest
from overseer.model import FleetModel
from overseer.model.shard import Shard
from overseer.sources.paced_drain import drain_paced
from overseer.sources.robot_naming import RobotNaming
from overseer.sources.topic_names import AGGREGATED, RAW
from overseer.sources.zenoh.keys import (
    BRIDGE,
    DIAGNOSTIC_ARRAY_HASH,
    RMW_ZENOH,
    DiagnosticsKey,
    RejectedKey,
    attachment_fields,
    bridge_liveliness_subscription,
    data_subscriptions,
    followed_subscription,
    liveliness_subscription,
    parse_bridge_token,
    parse_data_key,
    parse_publisher,
    unnamespaced_subscriptions,
)
from overseer.sources.zenoh.sequence_gaps import SequenceGaps
from overseer.sources.zenoh.session import session_config

log = logging.getLogger(__name__)

TRANSPORT = "zenoh"
RETRY_MIN_SECONDS = 0.5
RETRY_MAX_SECONDS = 10.0
TICK_SECONDS = 0.5  # how often publishers waiting for their token are looked at
PRUNE_INTERVAL_SECONDS = 60.0
ATTRIBUTION_GRACE_SECONDS = 3.0  # a publisher with no token by then (another rmw, a bridge): the domain's
MAX_TOKENS_PER_ROBOT = 64
MAX_PENDING_PUBLISHERS = 10_000
MAX_PENDING_SAMPLES = 16  # per publisher, while its robot is not known yet
MAX_FOREIGN_KEYS = 100_000  # keys remembered as another shard's or worker's (bounded against key floods)
MAX_FOLLOWED_TOPICS = 100_000  # per-topic subscriptions of a worker (bounded against token floods)


@dataclass
class _Unattributed:
    """Samples of an un-namespaced topic from a publisher whose token has not arrived yet."""

    parsed: DiagnosticsKey
    seen_at: float
    samples: list[bytes] = field(default_factory=list)


class ZenohSource:
    """Subscribes to every robot's diagnostics and publisher liveliness on one Zenoh session."""

    transport = TRANSPORT

    def __init__(
        self,
        config: ZenohConfig,
        model: FleetModel,
        shard: Shard | None = None,
        namespace_depth: int = DEFAULT_NAMESPACE_DEPTH,
    ) -> None:
        """Feed `model` from the Zenoh network in `config`; ConfigError at once if it is unusable."""
        self._config = config
        self._native = session_config(config)
        self._model = model
        self._shard = shard or Shard()
        self._naming = RobotNaming(config.unnamespaced_robot, config.robot_name is not None, namespace_depth)
        # Every ingest worker has a session and hears every key: what all of them see, the first counts.
        self._counts_shared_errors = self._shard.worker == 0
        self._lock = threading.Lock()
        # (robot, kind, publisher GID or b"") → its feed's ingest, None when not followed
        self._ingests: dict[tuple[str, str, bytes], PayloadIngest | None] = {}
        # robot → its feeds in `_ingests`: a new feed looks at its robot's, not at the whole fleet's
        self._feeds_of: dict[str, list[tuple[str, str, bytes]]] = {}
        # Every worker hears every robot's key: the others' are known by key, so they cost a set lookup.
        self._foreign: set[str] = set()
        self._tokens: dict[str, set[str]] = {}  # robot → live tokens of its diagnostics publishers
        self._publishers: dict[bytes, str] = {}  # GID → robot, from the publishers' tokens
        self._gaps = SequenceGaps()  # by publisher GID: what each sent and this session never heard
        self._unattributed: dict[bytes, _Unattributed] = {}
        self._session: zenoh.Session | None = None
        self._declared: list[zenoh.Subscriber[Any]] = []
        # A worker's share: a subscription per namespaced topic of its robots, all feeding one queue.
        self._partitioned = self._shard.count > 1 or self._shard.workers > 1
        self._samples: queue.SimpleQueue[zenoh.Sample | None] = queue.SimpleQueue()
        self._followed: dict[str, tuple[str, zenoh.Subscriber[Any] | None]] = {}  # key → robot, subscriber
        self._wake = threading.Event()  # a topic to follow is waiting for its subscription
        self.samples_heard = 0  # samples this session received, its robots' or not
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    def start(self) -> None:
        """Open the session in the background: routers that are not up yet are retried until they are."""
        self._thread = threading.Thread(target=self._run, name="zenoh-session", daemon=True)
        self._thread.start()

    def stop(self) -> None:
        """Undeclare everything and close the session."""
        self._stop.set()
        self._wake.set()
        with self._lock:
            session, self._session = self._session, None
            declared, self._declared = self._declared, []
            declared += [subscriber for _, subscriber in self._followed.values() if subscriber is not None]
            self._followed.clear()
        self._samples.put(None)
        for subscriber in declared:
            subscriber.undeclare()  # type: ignore[no-untyped-call]
        if session is not None:
            session.close()  # type: ignore[no-untyped-call]
        if self._thread is not None:
            self._thread.join(timeout=2)

    def _run(self) -> None:
        session = self._open()
        if session is None:
            return
        domain, formats = self._config.domain, self._config.key_formats
        # Declared without the lock held: the liveliness history is delivered to `_on_token`, which takes it.
        declared: list[zenoh.Subscriber[Any]] = []
        if self._partitioned:
            threading.Thread(target=self._drain_queue, name="zenoh-data", daemon=True).start()
        for key in unnamespaced_subscriptions(domain, formats) if self._partitioned else []:
            declared.append(session.declare_subscriber(key, self._queued()))
        for key in [] if self._partitioned else data_subscriptions(domain, formats):
            # Samples queue in a channel that Zenoh fills without the GIL, and a thread of ours drains it:
            # a callback would hold Zenoh's receiving thread on the GIL for every sample, so a busy moment
            # in Python would stall the link and the router would drop samples.
            subscriber = session.declare_subscriber(key, FifoChannel(self._config.queue_length))
            declared.append(subscriber)
            drain = threading.Thread(target=self._drain, args=(subscriber.handler,), name="zenoh-data")
            drain.daemon = True
            drain.start()
        liveliness = session.liveliness()
        tokens = [liveliness_subscription(domain)] if RMW_ZENOH in formats else []
        tokens += [bridge_liveliness_subscription()] if BRIDGE in formats else []
        declared += [liveliness.declare_subscriber(key, self._on_token, history=True) for key in tokens]
        with self._lock:
            stopped = self._stop.is_set()
            if not stopped:
                self._session, self._declared = session, declared
        if stopped:
            session.close()  # type: ignore[no-untyped-call]
            return
        log.info("Zenoh session %s open (%s)", session.zid(), self._native.get_json("mode"))
        pruned = time.monotonic()
        while not self._stop.is_set():
            self._wake.wait(TICK_SECONDS)
            self._wake.clear()
            if self._stop.is_set():
                break
            self._declare_followed(session)
            self._attribute_late()
            if time.monotonic() - pruned >= PRUNE_INTERVAL_SECONDS:
                pruned = time.monotonic()
                self._prune()

    def _open(self) -> zenoh.Session | None:
        delay = RETRY_MIN_SECONDS
        while not self._stop.is_set():
            try:
                return zenoh.open(self._native)
            except zenoh.ZError as error:
                if self._counts_shared_errors:
                    self._model.count_source_error(TRANSPORT, "router_unreachable")
                log.warning("cannot open the Zenoh session (retrying in %gs): %s", delay, error)
            self._stop.wait(delay)
            delay = min(delay * 2, RETRY_MAX_SECONDS)
        return None

    def _drain(self, channel: Any) -> None:
        """Hand every sample of one subscription's channel to `_on_data`, in batches, until it is closed."""

        def wait() -> zenoh.Sample | None:
            try:
                sample: zenoh.Sample = channel.recv()
            except zenoh.ZError:  # closed: the subscriber was undeclared
                return None
            return sample

        def poll() -> zenoh.Sample | None:
            try:
                sample: zenoh.Sample | None = channel.try_recv()
            except zenoh.ZError:
                return None
            return sample

        drain_paced(wait, poll, self._on_data, self._stop.is_set)

    def _queued(self) -> Callback[zenoh.Sample]:
        """A handler putting samples on the one queue `_drain_queue` reads, from Zenoh's own thread.

        It only enqueues: a worker's Python work is the ingest alone, so Zenoh's thread waits for the
        interpreter no longer than one sample's ingest.
        """
        return Callback(self._enqueue, indirect=False)

    def _enqueue(self, sample: zenoh.Sample) -> None:
        if self._samples.qsize() < self._config.queue_length:
            self._samples.put(sample)
        else:  # the ingest is that far behind (a flood): drop and count rather than grow without bound
            self._model.count_message(TRANSPORT, "dropped")
            attachment = None if sample.attachment is None else sample.attachment.to_bytes()
            gid, sequence = attachment_fields(attachment)
            if gid is not None and sequence is not None:
                self._gaps.heard(gid, sequence)  # counted dropped: not lost as well

    def _drain_queue(self) -> None:
        """Hand every queued sample to `_on_data`, in batches, until `stop`."""

        def poll() -> zenoh.Sample | None:
            try:
                return self._samples.get_nowait()
            except queue.Empty:
                return None

        drain_paced(self._samples.get, poll, self._on_data, self._stop.is_set)

    def _follow(self, topic: DiagnosticsKey, robot: str) -> None:
        """Ask for a subscription to one namespaced topic of a robot this worker owns."""
        key = followed_subscription(topic, self._config.domain)
        with self._lock:
            if key in self._followed or len(self._followed) >= MAX_FOLLOWED_TOPICS:
                return
            self._followed[key] = (robot, None)
        self._wake.set()

    def _declare_followed(self, session: zenoh.Session) -> None:
        """Declare the subscriptions `_follow` asked for (not from Zenoh's callback, which must not block)."""
        with self._lock:
            waiting = [key for key, (_, subscriber) in self._followed.items() if subscriber is None]
        for key in waiting:
            subscriber = session.declare_subscriber(key, self._queued())
            with self._lock:
                if key in self._followed and not self._stop.is_set():
                    self._followed[key] = (self._followed[key][0], subscriber)
                    continue
            subscriber.undeclare()  # type: ignore[no-untyped-call]

    def _on_data(self, sample: zenoh.Sample) -> None:
        self.samples_heard += 1
        try:
            key = str(sample.key_expr)
            if key in self._foreign:
                return
            try:
                parsed = parse_data_key(key, self._config.domain)
            except RejectedKey as rejected:
                if self._counts_shared_errors:
                    self._model.count_source_error(TRANSPORT, str(rejected))
                log.debug("ignoring Zenoh key %r: %s", key, rejected)
                return
            robot = self._naming.of_topic(parsed.namespace)
            if robot is not None and not self._shard.owns(robot):
                if len(self._foreign) < MAX_FOREIGN_KEYS:
                    self._foreign.add(key)
                return
            if parsed.key_format == RMW_ZENOH and parsed.type_hash != DIAGNOSTIC_ARRAY_HASH:
                # Another revision of the message: read anyway (the codec checks every byte), but say so.
                self._model.count_source_error(TRANSPORT, "type_hash_mismatch")
            attachment = None if sample.attachment is None else sample.attachment.to_bytes()
            publisher, sequence = attachment_fields(attachment)
            gid = publisher or b""
            payload = sample.payload.to_bytes()
            if robot is None:
                robot = self._publishers.get(gid) if gid else self._naming.unnamespaced_robot
                if robot is None:
                    self._hold(gid, parsed, payload)
                    return
                if not self._shard.owns(robot):
                    return
            ingest = self._ingest_for(robot, parsed, gid)
            if ingest is not None:
                if sequence is not None:
                    self._count_lost(robot, parsed, gid, sequence)
                ingest(payload)
        except DecodeError as error:  # already counted by the ingest
            log.debug("undecodable sample on %s: %s", sample.key_expr, error)
        except Exception:  # a callback from Zenoh's threads must never raise
            log.exception("failed to process diagnostics from %s", sample.key_expr)

    def _count_lost(self, robot: str, parsed: DiagnosticsKey, gid: bytes, sequence: int) -> None:
        """Count the samples a publisher sent before `sequence` and this session never heard."""
        missed = self._gaps.missed(gid, sequence)
        if missed:
            self._model.count_message(TRANSPORT, "lost", missed)
            lost = self._gaps.lost(gid)
            before = lost - missed
            if not before or len(str(lost)) > len(str(before)):  # its first loss, then at each power of ten
                log.warning(
                    "%d samples of %s's %s (publisher %s) never heard so far: the router or the link "
                    "dropped them, or this exporter could not keep up",
                    lost,
                    robot,
                    parsed.topic,
                    gid.hex(),
                )

    def _hold(self, gid: bytes, parsed: DiagnosticsKey, payload: bytes) -> None:
        """Keep a sample of a publisher whose token (whose node) is not known yet."""
        with self._lock:
            waiting = self._unattributed.get(gid)
            if waiting is None:
                if len(self._unattributed) >= MAX_PENDING_PUBLISHERS:
                    return
                waiting = self._unattributed[gid] = _Unattributed(parsed, time.monotonic())
            if len(waiting.samples) < MAX_PENDING_SAMPLES:
                waiting.samples.append(payload)
            else:
                waiting.samples[-1] = payload  # the newest says the most

    def _release(self, gid: bytes, robot: str) -> None:
        """Hand a publisher's held samples to its robot, now that its robot is known."""
        with self._lock:
            waiting = self._unattributed.pop(gid, None)
        if waiting is None or not self._shard.owns(robot):
            return
        ingest = self._ingest_for(robot, waiting.parsed, gid)
        if ingest is None:
            return
        for payload in waiting.samples:
            with contextlib.suppress(DecodeError):  # counted by the ingest
                ingest(payload)

    def _attribute_late(self) -> None:
        """Publishers heard with no token within the grace belong to the domain's robot."""
        now = time.monotonic()
        waiting = list(self._unattributed.items())
        late = [gid for gid, held in waiting if now - held.seen_at >= ATTRIBUTION_GRACE_SECONDS]
        for gid in late:
            with self._lock:
                self._publishers.setdefault(gid, self._naming.unnamespaced_robot)
            self._release(gid, self._naming.unnamespaced_robot)

    def _ingest_for(self, robot: str, parsed: DiagnosticsKey, gid: bytes) -> PayloadIngest | None:
        """The ingest of a publisher's feed; None when it is not followed (raw beside aggregated, cap)."""
        feed = (robot, parsed.kind, gid)
        ingest = self._ingests.get(feed)
        if ingest is not None or feed in self._ingests:
            return ingest
        with self._lock:
            if feed in self._ingests:
                return self._ingests[feed]
            feeds = self._feeds_of.get(robot, [])
            if parsed.kind == RAW and any(kind == AGGREGATED for _, kind, _ in feeds):
                self._add_feed(feed, None)  # a robot publishing both is read from diagnostics_agg only
                return None
            if not self._model.register(robot, TRANSPORT):
                self._model.count_message(TRANSPORT, "dropped")
                return None
            if parsed.kind == AGGREGATED:
                for key in [key for key in feeds if key[1] == RAW]:
                    self._ingests[key] = None
                    self._model.forget_topic(robot, parsed.topic[: -len(AGGREGATED)] + RAW)
            name = f"{parsed.topic}@{gid.hex()}" if gid else parsed.topic
            ingest = PayloadIngest(self._model, robot, TRANSPORT, parsed.topic, cdr.WIRE_FORMAT, name)
            self._add_feed(feed, ingest)
            log.info("following robot %s over Zenoh (%s, %s)", robot, parsed.topic, parsed.key_format)
            return ingest

    def _add_feed(self, feed: tuple[str, str, bytes], ingest: PayloadIngest | None) -> None:
        """Remember a feed's ingest (None: not followed), under `_lock`."""
        self._ingests[feed] = ingest
        self._feeds_of.setdefault(feed[0], []).append(feed)

    def _on_token(self, sample: zenoh.Sample) -> None:
        try:
            key = str(sample.key_expr)
            publisher = parse_publisher(key, self._config.domain)
            gid = b""
            if publisher is not None:
                topic, gid = publisher.topic, publisher.gid
                robot = self._naming.of_topic(topic.namespace)
                robot = robot if robot is not None else self._naming.of_node(publisher.node_namespace)
            else:
                bridged = parse_bridge_token(key)
                if bridged is None:
                    return
                topic, robot = bridged, bridged.namespace or self._config.unnamespaced_robot
            if robot is None:
                self._model.count_source_error(TRANSPORT, "invalid_namespace")
                return
            alive = sample.kind == zenoh.SampleKind.PUT
            if gid and alive:
                with self._lock:
                    self._publishers[gid] = robot
                self._release(gid, robot)
            if not self._shard.owns(robot):
                return
            if alive and self._partitioned and topic.namespace:
                self._follow(topic, robot)  # a robot beyond the cap too: its samples are counted as dropped
            with self._lock:
                tokens = self._tokens.get(robot)
                if alive:
                    if not self._model.register(robot, TRANSPORT):
                        return
                    tokens = self._tokens.setdefault(robot, set())
                    if len(tokens) < MAX_TOKENS_PER_ROBOT:
                        tokens.add(key)
                elif tokens is not None:
                    tokens.discard(key)
                    if not tokens:
                        del self._tokens[robot]
                        self._model.publisher_left(robot)
                else:
                    return
            log.info("diagnostics publisher of %s %s", robot, "appeared" if alive else "went away")
        except Exception:  # a callback from Zenoh's threads must never raise
            log.exception("failed to process liveliness token %s", sample.key_expr)

    def _prune(self) -> None:
        """Forget the ingests, tokens and publishers of robots the model has forgotten (expired)."""
        known = {robot.name for robot in self._model.snapshot().robots}
        with self._lock:
            for robot in [robot for robot in self._feeds_of if robot not in known]:
                for feed in self._feeds_of.pop(robot):
                    del self._ingests[feed]
                    self._gaps.forget(feed[2])
            for robot in [robot for robot in self._tokens if robot not in known]:
                del self._tokens[robot]
            gone = [key for key, (robot, _) in self._followed.items() if robot not in known]
            unfollowed = [self._followed.pop(key)[1] for key in gone]
            owns = self._shard.owns
            for gid in [gid for gid, robot in self._publishers.items() if robot not in known and owns(robot)]:
                del self._publishers[gid]
        for subscriber in unfollowed:
            if subscriber is not None:
                subscriber.undeclare()  # type: ignore[no-untyped-call]
