"""The Zenoh transport: robots on rmw_zenoh (ROS 2 Jazzy) and robots behind zenoh-bridge-ros2dds.

One Zenoh session (a client of the configured routers by default) subscribes to every robot's
diagnostics keys with wildcards, so robots that start later, or were built against another revision of
the message (another type hash), are heard with no restart. Payloads are DDS CDR and go through the
same ingest as DDS samples. rmw_zenoh's liveliness tokens tell when a robot's diagnostics publisher
goes (process killed, link lost), and so do zenoh-bridge-ros2dds's tokens for the routes it serves:
the robot is down at once, not after `robot_timeout`.
"""

from __future__ import annotations

import logging
import threading
from typing import Any

import zenoh
from zenoh.handlers import FifoChannel

from overseer.codec import DecodeError, cdr
from overseer.config.zenoh import ZenohConfig
from overseer.ingest.payload import PayloadIngest
from overseer.model import FleetModel
from overseer.model.shard import Shard
from overseer.sources.topic_names import AGGREGATED, RAW
from overseer.sources.zenoh.keys import (
    BRIDGE,
    DIAGNOSTIC_ARRAY_HASH,
    RMW_ZENOH,
    DiagnosticsKey,
    RejectedKey,
    bridge_liveliness_subscription,
    data_subscriptions,
    liveliness_subscription,
    parse_bridge_token,
    parse_data_key,
    parse_publisher_token,
)
from overseer.sources.zenoh.session import session_config

log = logging.getLogger(__name__)

TRANSPORT = "zenoh"
RETRY_MIN_SECONDS = 0.5
RETRY_MAX_SECONDS = 10.0
PRUNE_INTERVAL_SECONDS = 60.0
MAX_TOKENS_PER_ROBOT = 64
MAX_FOREIGN_KEYS = 100_000  # keys remembered as another shard's or worker's (bounded against key floods)
CHANNEL_CAPACITY = 8192  # samples waiting for the ingest, per subscription (about 4 kB each at 50 components)


class ZenohSource:
    """Subscribes to every robot's diagnostics and publisher liveliness on one Zenoh session."""

    transport = TRANSPORT

    def __init__(self, config: ZenohConfig, model: FleetModel, shard: Shard | None = None) -> None:
        """Feed `model` from the Zenoh network in `config`; ConfigError at once if it is unusable."""
        self._config = config
        self._native = session_config(config)
        self._model = model
        self._shard = shard or Shard()
        # Every ingest worker has a session and hears every key: what all of them see, the first counts.
        self._counts_shared_errors = self._shard.worker == 0
        self._lock = threading.Lock()
        self._ingests: dict[tuple[str, str], PayloadIngest] = {}  # (robot, kind) → its topic's ingest
        # Every worker hears every robot's key: the others' are known by key, so they cost a set lookup.
        self._foreign: set[str] = set()
        self._tokens: dict[str, set[str]] = {}  # robot → live tokens of its diagnostics publishers
        self._session: zenoh.Session | None = None
        self._declared: list[zenoh.Subscriber[Any]] = []
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    def start(self) -> None:
        """Open the session in the background: routers that are not up yet are retried until they are."""
        self._thread = threading.Thread(target=self._run, name="zenoh-session", daemon=True)
        self._thread.start()

    def stop(self) -> None:
        """Undeclare everything and close the session."""
        self._stop.set()
        with self._lock:
            session, self._session = self._session, None
            declared, self._declared = self._declared, []
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
        for key in data_subscriptions(domain, formats):
            # Samples queue in a channel that Zenoh fills without the GIL, and a thread of ours drains it:
            # a callback would hold Zenoh's receiving thread on the GIL for every sample, so a busy moment
            # in Python would stall the link and the router would drop samples.
            subscriber = session.declare_subscriber(key, FifoChannel(CHANNEL_CAPACITY))
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
        while not self._stop.wait(PRUNE_INTERVAL_SECONDS):
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
        """Hand every sample of one subscription's channel to `_on_data` until it is closed."""
        while True:
            try:
                sample = channel.recv()
            except zenoh.ZError:  # closed: the subscriber was undeclared
                return
            self._on_data(sample)

    def _on_data(self, sample: zenoh.Sample) -> None:
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
            robot = parsed.namespace or self._config.unnamespaced_robot
            if not self._shard.owns(robot):
                if len(self._foreign) < MAX_FOREIGN_KEYS:
                    self._foreign.add(key)
                return
            if parsed.key_format == RMW_ZENOH and parsed.type_hash != DIAGNOSTIC_ARRAY_HASH:
                # Another revision of the message: read anyway (the codec checks every byte), but say so.
                self._model.count_source_error(TRANSPORT, "type_hash_mismatch")
            ingest = self._ingest_for(robot, parsed)
            if ingest is not None:
                ingest(sample.payload.to_bytes())
        except DecodeError as error:  # already counted by the ingest
            log.debug("undecodable sample on %s: %s", sample.key_expr, error)
        except Exception:  # a callback from Zenoh's threads must never raise
            log.exception("failed to process diagnostics from %s", sample.key_expr)

    def _ingest_for(self, robot: str, parsed: DiagnosticsKey) -> PayloadIngest | None:
        """The ingest of the robot's topic; None when it is not followed (raw beside aggregated, cap)."""
        with self._lock:
            ingest = self._ingests.get((robot, parsed.kind))
            if ingest is not None:
                return ingest
            if parsed.kind == RAW and (robot, AGGREGATED) in self._ingests:
                return None  # a robot publishing both is read from diagnostics_agg only
            if not self._model.register(robot, TRANSPORT):
                self._model.count_message(TRANSPORT, "dropped")
                return None
            if parsed.kind == AGGREGATED and self._ingests.pop((robot, RAW), None) is not None:
                self._model.forget_topic(robot, parsed.topic[: -len(AGGREGATED)] + RAW)
            ingest = PayloadIngest(self._model, robot, TRANSPORT, parsed.topic, cdr.WIRE_FORMAT)
            self._ingests[(robot, parsed.kind)] = ingest
            log.info("following robot %s over Zenoh (%s, %s)", robot, parsed.topic, parsed.key_format)
            return ingest

    def _on_token(self, sample: zenoh.Sample) -> None:
        try:
            key = str(sample.key_expr)
            parsed = parse_publisher_token(key, self._config.domain) or parse_bridge_token(key)
            if parsed is None:
                return
            robot = parsed.namespace or self._config.unnamespaced_robot
            if not self._shard.owns(robot):
                return
            alive = sample.kind == zenoh.SampleKind.PUT
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
                else:
                    return
                self._model.set_publisher_alive(robot, robot in self._tokens)
            log.info("diagnostics publisher of %s %s", robot, "appeared" if alive else "went away")
        except Exception:  # a callback from Zenoh's threads must never raise
            log.exception("failed to process liveliness token %s", sample.key_expr)

    def _prune(self) -> None:
        """Forget the ingests and tokens of robots the model has forgotten (expired)."""
        known = {robot.name for robot in self._model.snapshot().robots}
        with self._lock:
            for key in [key for key in self._ingests if key[0] not in known]:
                del self._ingests[key]
            for robot in [robot for robot in self._tokens if robot not in known]:
                del self._tokens[robot]
