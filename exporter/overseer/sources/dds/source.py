"""The ROS 2 transport: join DDS domains with Cyclone DDS, discover robots, read raw diagnostics.

Robots are found on the DDS built-in publication topic: every writer of `rt/<ns>/diagnostics_agg` or
`rt/<ns>/diagnostics` is robot `<ns>`, so a robot that starts later is picked up with no restart.
Samples are taken as raw CDR and decoded by `overseer.codec.cdr`, which is faster than the generic
deserializer and turns a malformed payload into a counted `decode_error` instead of an exception.

A writer leaving (a clean exit, or its lease running out) is announced on the same topic: when a robot's
last diagnostics writer leaves, the robot is down at once, not after `robot_timeout`.

A reliable reader never matches a best-effort writer (micro-ROS nodes, sensor-data QoS), while a
best-effort reader matches both: a topic is read reliably while every writer of it is reliable, and
best-effort from the first best-effort writer on (the discovery sample tells each writer's reliability).
"""

from __future__ import annotations

import logging
import os
import threading
from dataclasses import dataclass, field
from typing import Any

from cyclonedds._clayer import ddspy_take
from cyclonedds.builtin import BuiltinDataReader, BuiltinTopicDcpsPublication
from cyclonedds.core import InstanceState, Listener, Policy, Qos, SampleState, ViewState
from cyclonedds.domain import DomainParticipant
from cyclonedds.sub import DataReader, Subscriber
from cyclonedds.topic import Topic
from cyclonedds.util import duration

from overseer.codec import DecodeError, cdr
from overseer.config.dds import DdsConfig, DdsPeer, DomainConfig
from overseer.ingest.payload import PayloadIngest
from overseer.model import FleetModel
from overseer.model.shard import Shard
from overseer.sources.dds.cyclone_config import (
    LOOPBACK_MAX_PARTICIPANTS,
    configure_domain,
    loopback_only_config,
    peers_config,
)
from overseer.sources.dds.cyclone_log import CycloneWarnings
from overseer.sources.dds.peers import peer_addresses
from overseer.sources.dds.types import DIAGNOSTIC_ARRAY_TYPE_NAME, DiagnosticArray
from overseer.sources.topic_names import AGGREGATED, RAW, parse_dds_topic

log = logging.getLogger(__name__)

TRANSPORT = "dds"
DISCOVERY_INTERVAL_SECONDS = 0.2
_TAKE_BATCH = 64
_ANY_SAMPLE = SampleState.Any | ViewState.Any | InstanceState.Any

# ROS 2's default QoS profile for topics. Readers stay volatile so they match both volatile
# and transient-local writers.
ROS_DEFAULT_QOS = Qos(
    Policy.Reliability.Reliable(duration(milliseconds=100)),
    Policy.Durability.Volatile,
    Policy.History.KeepLast(10),
)
# For topics with a best-effort writer: matches reliable and best-effort writers alike.
BEST_EFFORT_QOS = Qos(Policy.Reliability.BestEffort, Policy.Durability.Volatile, Policy.History.KeepLast(10))


@dataclass
class _DomainSession:
    config: DomainConfig
    participant: DomainParticipant
    subscriber: Subscriber
    publications: BuiltinDataReader
    readers: dict[str, DataReader[DiagnosticArray]] = field(default_factory=dict)
    writers: dict[Any, str] = field(default_factory=dict)  # publication key → DDS topic name
    best_effort_topics: set[str] = field(default_factory=set)  # a writer of each is best-effort


class DdsSource:
    """Subscribes to every robot's diagnostics on the configured DDS domains."""

    transport = TRANSPORT

    def __init__(self, config: DdsConfig, model: FleetModel, shard: Shard | None = None) -> None:
        """Feed `model` from the domains in `config`, following only `shard`'s robots; joins on `start`."""
        self._config = config
        self._model = model
        self._shard = shard or Shard()
        self._sessions: list[_DomainSession] = []
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    def start(self) -> None:
        """Join every configured domain and start discovering robots."""
        warnings = CycloneWarnings(self._count_dropped_sample)
        base = loopback_only_config() if self._config.loopback_only else self._config.cyclonedds_uri
        # An explicit configuration replaces CYCLONEDDS_URI, so the operator's one is kept in front;
        # the peers come after it, adding to any peers it lists.
        fragments = [base or os.environ.get("CYCLONEDDS_URI", ""), self._peers_config(), warnings.config()]
        config = ",".join(fragment for fragment in fragments if fragment)
        for domain_config in self._config.domains:
            configure_domain(domain_config.id, config)
            participant = DomainParticipant(domain_config.id)
            publications = BuiltinDataReader(participant, BuiltinTopicDcpsPublication)
            self._sessions.append(
                _DomainSession(domain_config, participant, Subscriber(participant), publications)
            )
        self._discover()
        self._thread = threading.Thread(target=self._discovery_loop, name="dds-discovery", daemon=True)
        self._thread.start()

    def stop(self) -> None:
        """Stop discovery and leave every domain."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=5)
        self._sessions.clear()

    def _peers_config(self) -> str:
        max_index = self._config.max_participant_index
        if self._config.loopback_only:
            max_index = max(max_index, LOOPBACK_MAX_PARTICIPANTS)
        addresses = peer_addresses(self._config.peers, self._count_unresolved_peer)
        if addresses:
            log.info("DDS discovery also goes to %s (indices 0-%d)", ", ".join(addresses), max_index)
        return peers_config(addresses, max_index)

    def _count_unresolved_peer(self, peer: DdsPeer, error: str) -> None:
        if self._shard.worker != 0:
            return  # every ingest worker resolves the same peers: the first counts and tells for all
        self._model.count_source_error(TRANSPORT, "peer_unresolved")
        log.warning("DDS peer %s left out: cannot resolve it (%s)", peer, error)

    def _count_dropped_sample(self, warning: str) -> None:
        self._model.count_message(TRANSPORT, "decode_error")
        log.warning("malformed sample dropped: %s", warning)

    @property
    def subscribed_topics(self) -> list[tuple[int, str]]:
        """(domain id, DDS topic) of every reader created so far."""
        return [(s.config.id, topic) for s in self._sessions for topic in s.readers]

    def _discovery_loop(self) -> None:
        while not self._stop.wait(DISCOVERY_INTERVAL_SECONDS):
            try:
                self._discover()
            except Exception:  # discovery must outlive any one bad sample
                log.exception("DDS discovery failed; retrying")

    def _discover(self) -> None:
        for session in self._sessions:
            for sample in session.publications.take(N=256):
                topic_name = sample.topic_name
                if topic_name is None:
                    left = session.writers.pop(sample.key, None)
                    if left is not None:
                        self._writer_left(session, left)
                    continue
                if parse_dds_topic(topic_name) is None:
                    continue
                if sample.type_name != DIAGNOSTIC_ARRAY_TYPE_NAME:
                    log.warning(
                        "ignoring %s on domain %d: type %s", topic_name, session.config.id, sample.type_name
                    )
                    continue
                session.writers[sample.key] = topic_name
                if sample.qos[Policy.Reliability] == Policy.Reliability.BestEffort:
                    self._read_best_effort(session, topic_name)
                self._subscribe(session, topic_name)
                robot = self._robot_of(session, topic_name)
                if robot is not None:
                    self._model.set_publisher_alive(robot, True)

    def _robot_of(self, session: _DomainSession, topic_name: str) -> str | None:
        parsed = parse_dds_topic(topic_name)
        return None if parsed is None else parsed.namespace or session.config.unnamespaced_robot

    def _writer_left(self, session: _DomainSession, topic_name: str) -> None:
        """A writer of `topic_name` left: its robot is down at once when no writer of its topics is left."""
        robot = self._robot_of(session, topic_name)
        if robot is None:
            return
        remaining = {
            self._robot_of(other, name) for other in self._sessions for name in other.writers.values()
        }
        if robot not in remaining:
            self._model.set_publisher_alive(robot, False)
            log.info("robot %s: its last diagnostics writer left", robot)

    def _read_best_effort(self, session: _DomainSession, topic_name: str) -> None:
        """From now on read `topic_name` best-effort: a reliable reader never hears its new writer."""
        if topic_name in session.best_effort_topics:
            return
        session.best_effort_topics.add(topic_name)
        reader = session.readers.pop(topic_name, None)
        if reader is not None:
            reader.__del__()  # `_subscribe` creates its best-effort successor
            log.info(
                "reading %s on domain %d best-effort, as a writer of it is", topic_name, session.config.id
            )

    def _subscribe(self, session: _DomainSession, topic_name: str) -> None:
        parsed = parse_dds_topic(topic_name)
        if parsed is None or topic_name in session.readers or parsed.kind not in self._config.topics:
            return
        robot = parsed.namespace or session.config.unnamespaced_robot
        if not self._shard.owns(robot):
            return
        sibling = topic_name[: -len(parsed.kind)] + (RAW if parsed.kind == AGGREGATED else AGGREGATED)
        if self._config.prefer_aggregated and AGGREGATED in self._config.topics:
            if parsed.kind == RAW and sibling in session.readers:
                return
            if parsed.kind == AGGREGATED and sibling in session.readers:
                session.readers.pop(sibling).__del__()
                self._model.forget_topic(robot, sibling)
        if not self._model.register(robot, TRANSPORT):
            log.warning("robot cap reached; not following %s on domain %d", topic_name, session.config.id)
            return
        qos = BEST_EFFORT_QOS if topic_name in session.best_effort_topics else ROS_DEFAULT_QOS
        topic = Topic(session.participant, topic_name, DiagnosticArray, qos=ROS_DEFAULT_QOS)
        listener = Listener(on_data_available=self._on_data_callback(robot, topic_name))  # type: ignore[no-untyped-call]
        session.readers[topic_name] = DataReader(session.subscriber, topic, qos=qos, listener=listener)
        log.info("following robot %s on domain %d (%s)", robot, session.config.id, topic_name)

    def _on_data_callback(self, robot: str, topic_name: str) -> Any:
        ingest = PayloadIngest(self._model, robot, TRANSPORT, topic_name, cdr.WIRE_FORMAT)

        def on_data_available(reader: DataReader[DiagnosticArray]) -> None:
            try:
                while True:
                    samples = ddspy_take(reader._ref, _ANY_SAMPLE, _TAKE_BATCH)
                    if isinstance(samples, int):
                        log.warning("take on %s failed with DDS error %d", topic_name, samples)
                        return
                    for data, info in samples:
                        if info.valid_data:
                            try:
                                ingest(data)
                            except DecodeError as error:
                                log.debug("undecodable sample on %s: %s", topic_name, error)
                    if len(samples) < _TAKE_BATCH:
                        return
            except Exception:  # a callback from the DDS thread must never raise
                log.exception("failed to process diagnostics from %s", topic_name)

        return on_data_available
