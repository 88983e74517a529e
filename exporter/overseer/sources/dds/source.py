"""The ROS 2 transport: join DDS domains with Cyclone DDS, discover robots, read raw diagnostics.

Robots are found on the DDS built-in publication topic: every writer of `rt/<ns>/diagnostics_agg` or
`rt/<ns>/diagnostics` is robot `<ns>`, so a robot that starts later is picked up with no restart. A writer
of an un-namespaced topic (`rt/diagnostics`, where diagnostic_updater publishes whatever its node's
namespace) belongs to the robot its node's namespace names, read from the ROS graph the robot's rmw
publishes (`node_graph.py`, `robot_naming.py`); on a domain given a `robot_name`, to that one robot. A
writer whose node the graph has not told within a grace is the domain's robot's until the graph tells it
(`reattribution.py`).
Each writer is a feed of its robot: nodes sharing one robot's `/diagnostics` each send their own statuses.
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
import time
from dataclasses import dataclass, field
from typing import Any

from cyclonedds._clayer import ddspy_take
from cyclonedds.builtin import BuiltinDataReader, BuiltinTopicDcpsPublication
from cyclonedds.core import InstanceState, Listener, Policy, Qos, SampleState, ViewState
from cyclonedds.domain import DomainParticipant
from cyclonedds.sub import DataReader, Subscriber
from cyclonedds.topic import Topic
from cyclonedds.util import duration

from overseer.config.dds import DdsConfig, DdsPeer, DomainConfig
from overseer.config.fleet import DEFAULT_NAMESPACE_DEPTH
from overseer.model import FleetModel
from overseer.model.shard import Shard
from overseer.sources.dds.cyclone_config import (
    LOOPBACK_MAX_PARTICIPANTS,
    configure_domain,
    loopback_only_config,
    peers_config,
)
from overseer.sources.dds.cyclone_log import CycloneWarnings
from overseer.sources.dds.node_graph import NodeGraph
from overseer.sources.dds.peers import peer_addresses
from overseer.sources.dds.sink import TRANSPORT, DdsSink, Ingest, ModelSink, take_sample
from overseer.sources.dds.types import DIAGNOSTIC_ARRAY_TYPE_NAME, DiagnosticArray
from overseer.sources.reattribution import MovedFeeds
from overseer.sources.robot_naming import RobotNaming
from overseer.sources.topic_names import AGGREGATED, RAW, parse_dds_topic

log = logging.getLogger(__name__)

DISCOVERY_INTERVAL_SECONDS = 0.2
# How long a writer of an un-namespaced topic waits for its node to appear in the graph before it is taken
# for the domain's robot (a DDS application that is no ROS 2 node never appears there). Fast DDS sends a
# reader that matched after its graph was written that graph at its next heartbeat, up to 3 s later: a
# little more than that, so that a node is seldom its domain's robot for a while.
ATTRIBUTION_GRACE_SECONDS = 4.0
MAX_PENDING_SAMPLES = 16  # per writer, while its robot is not known yet
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
class _Writer:
    """One DDS writer of a diagnostics topic: its robot once known, and the ingest of its feed."""

    topic: str
    kind: str
    guid: bytes
    robot: str | None
    seen_at: float  # monotonic
    ingest: Ingest | None = None
    ignored: bool = False  # another worker's robot, the robot cap, or raw beside aggregated
    pending: list[bytes] = field(default_factory=list)  # samples heard before its robot was known
    by_domain: bool = False  # the domain's robot's, as its node was not in the graph within the grace


@dataclass
class _DomainSession:
    config: DomainConfig
    naming: RobotNaming
    participant: DomainParticipant
    subscriber: Subscriber
    publications: BuiltinDataReader
    graph: NodeGraph | None  # the ROS graph, where un-namespaced topics are named by their nodes
    readers: dict[str, DataReader[DiagnosticArray]] = field(default_factory=dict)
    writers: dict[int, _Writer] = field(default_factory=dict)  # by publication (instance) handle
    best_effort_topics: set[str] = field(default_factory=set)  # a writer of each is best-effort


class DdsSource:
    """Subscribes to every robot's diagnostics on the configured DDS domains."""

    transport = TRANSPORT

    def __init__(
        self,
        config: DdsConfig,
        model: FleetModel | DdsSink,
        shard: Shard | None = None,
        namespace_depth: int = DEFAULT_NAMESPACE_DEPTH,
    ) -> None:
        """Feed `model` from the domains in `config`, following only `shard`'s robots; joins on `start`.

        `model` is the fleet model of this process, or a sink that hands the robots on (`relay.py`).
        """
        self._config = config
        self._model: DdsSink = ModelSink(model) if isinstance(model, FleetModel) else model
        self._shard = shard or Shard()
        self._namespace_depth = namespace_depth
        self._sessions: list[_DomainSession] = []
        self._lock = threading.Lock()  # the writers' pending samples and ingests, between listener threads
        self._robot_writers: dict[str, list[_Writer]] = {}  # robot → its live writers, across domains
        self._aggregated: set[str] = set()  # robots read from diagnostics_agg only
        self._moved = MovedFeeds(self._model)
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
            subscriber = Subscriber(participant)
            naming = RobotNaming(
                domain_config.unnamespaced_robot, domain_config.robot_name is not None, self._namespace_depth
            )
            graph = None if naming.named else NodeGraph(participant, subscriber)
            self._sessions.append(
                _DomainSession(domain_config, naming, participant, subscriber, publications, graph)
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
        self._moved.forget(self._robot_writers.__contains__)
        for session in self._sessions:
            graph_changed = session.graph is not None and session.graph.poll()
            for sample in session.publications.take(N=256):
                handle = sample.sample_info.instance_handle
                topic_name = sample.topic_name
                if topic_name is None:
                    self._writer_left(session, handle)
                    continue
                parsed = parse_dds_topic(topic_name)
                if parsed is None or parsed.kind not in self._config.topics:
                    continue
                if sample.type_name != DIAGNOSTIC_ARRAY_TYPE_NAME:
                    log.warning(
                        "ignoring %s on domain %d: type %s", topic_name, session.config.id, sample.type_name
                    )
                    continue
                if sample.qos[Policy.Reliability] == Policy.Reliability.BestEffort:
                    self._read_best_effort(session, topic_name)
                self._subscribe(session, topic_name)
                robot = session.naming.of_topic(parsed.namespace)
                with self._lock:
                    writer = session.writers.get(handle)
                    if writer is None:
                        writer = session.writers[handle] = _Writer(topic_name, parsed.kind, b"", None, 0.0)
                    if writer.guid:
                        continue  # known already (a writer's QoS changed)
                    writer.topic, writer.kind, writer.guid = topic_name, parsed.kind, sample.key.bytes
                    writer.seen_at = time.monotonic()
                if robot is not None:
                    self._adopt(writer, robot)
            if graph_changed or any(w.robot is None for w in session.writers.values()):
                self._attribute(session)

    def _attribute(self, session: _DomainSession) -> None:
        """Name the robots of un-namespaced topics' writers by their nodes, or the domain's after a grace.

        A writer given the domain's robot moves to its node's robot when the graph names the node later.
        """
        now = time.monotonic()
        for writer in list(session.writers.values()):
            if (writer.robot is not None and not writer.by_domain) or not writer.guid:
                continue
            robot = self._robot_of_node(session, writer.guid)
            if writer.robot is not None:  # the domain's robot's: moved once its node is told
                if robot is not None:
                    writer.by_domain = False
                    if robot != writer.robot:
                        self._move(writer, robot)
            elif robot is not None:
                self._adopt(writer, robot)
            elif now - writer.seen_at >= ATTRIBUTION_GRACE_SECONDS:
                writer.by_domain = True
                log.info("a writer of %s is no ROS 2 node's as yet: the domain's robot", writer.topic)
                self._adopt(writer, session.naming.unnamespaced_robot)

    def _robot_of_node(self, session: _DomainSession, guid: bytes) -> str | None:
        """The robot of the node that owns writer `guid`, when the graph has told it."""
        node = None if session.graph is None else session.graph.node_of(guid)
        if node is None:
            return None
        robot = session.naming.of_node(node.namespace)
        if robot is None:
            self._model.count_source_error(TRANSPORT, "invalid_namespace")
            log.warning("node %r has an invalid namespace %r", node.name, node.namespace)
            return session.naming.unnamespaced_robot
        return robot

    def _move(self, writer: _Writer, robot: str) -> None:
        """Follow a writer taken for its domain's robot as a feed of `robot`, its node's."""
        old = writer.robot
        assert old is not None
        with self._lock:  # what arrives from now on waits in `pending` for the new ingest
            followed, writer.ingest, writer.ignored = writer.ingest is not None, None, False
        self._drop_writer(old, writer)
        if followed:
            self._model.released(old, writer.topic, _feed_name(writer))
            self._moved.moved(old, _feed_name(writer))
        log.info("writer %s of %s: a node of robot %s, not %s", writer.guid.hex(), writer.topic, robot, old)
        self._adopt(writer, robot)

    def _adopt(self, writer: _Writer, robot: str) -> None:
        """Follow `writer` as a feed of `robot` (when this source follows the robot), its pending first."""
        writer.robot = robot
        self._robot_writers.setdefault(robot, []).append(writer)
        if not self._shard.owns(robot):
            writer.ignored = True
        elif writer.kind == RAW and robot in self._aggregated and AGGREGATED in self._config.topics:
            writer.ignored = True  # the robot's aggregator says it all
        elif not self._model.register(robot, TRANSPORT):
            writer.ignored = True
            log.warning("robot cap reached; not following robot %s (%s)", robot, writer.topic)
        if writer.ignored:
            with self._lock:
                writer.pending.clear()
            return
        if writer.kind == AGGREGATED and self._config.prefer_aggregated and robot not in self._aggregated:
            self._aggregated.add(robot)
            self._ignore_raw(robot)
        feed = _feed_name(writer)
        ingest = self._model.ingest(robot, writer.topic, feed)
        while True:  # what arrived meanwhile, in order, before new samples go straight to the ingest
            with self._lock:
                pending, writer.pending = writer.pending, []
                if not pending:
                    writer.ingest = ingest
                    break
            for payload in pending:
                take_sample(ingest, payload, writer.topic)
        log.info("following robot %s (%s, writer %s)", robot, writer.topic, writer.guid.hex())

    def _ignore_raw(self, robot: str) -> None:
        """Leave a robot's raw diagnostics writers once it has an aggregator: forget what they said."""
        for writer in self._robot_writers.get(robot, []):
            if writer.kind == RAW and not writer.ignored:
                followed, writer.ignored, writer.ingest = writer.ingest is not None, True, None
                if followed:
                    self._model.released(robot, writer.topic, _feed_name(writer))
                self._model.forget_topic(robot, writer.topic)

    def _writer_left(self, session: _DomainSession, handle: int) -> None:
        """A writer left: its robot is down at once when no writer of its diagnostics is left."""
        with self._lock:
            writer = session.writers.pop(handle, None)
        if writer is None or writer.robot is None:
            return
        robot = writer.robot
        if writer.ingest is not None:
            self._model.released(robot, writer.topic, _feed_name(writer))
        if self._drop_writer(robot, writer) and self._shard.owns(robot):
            self._model.publisher_left(robot)
            log.info("robot %s: its last diagnostics writer left", robot)

    def _drop_writer(self, robot: str, writer: _Writer) -> bool:
        """`writer` is no longer one of `robot`'s; True when it was its last."""
        writers = [other for other in self._robot_writers.get(robot, []) if other is not writer]
        if writers:
            self._robot_writers[robot] = writers
            return False
        self._robot_writers.pop(robot, None)
        return True

    def _read_best_effort(self, session: _DomainSession, topic_name: str) -> None:
        """From now on read `topic_name` best-effort: a reliable reader never hears its new writer."""
        if topic_name in session.best_effort_topics:
            return
        session.best_effort_topics.add(topic_name)
        reader = session.readers.pop(topic_name, None)
        if reader is not None:
            reader.__del__()  # `_subscribe` creates its best-effort successor

    def _subscribe(self, session: _DomainSession, topic_name: str) -> None:
        parsed = parse_dds_topic(topic_name)
        if parsed is None or topic_name in session.readers or parsed.kind not in self._config.topics:
            return
        robot = session.naming.of_topic(parsed.namespace)
        if robot is not None and not self._shard.owns(robot):
            return
        if parsed.namespace and self._config.prefer_aggregated and AGGREGATED in self._config.topics:
            sibling = topic_name[: -len(parsed.kind)] + (RAW if parsed.kind == AGGREGATED else AGGREGATED)
            if parsed.kind == RAW and sibling in session.readers:
                return  # a namespaced robot's raw topic is not even read beside its aggregator's
            if parsed.kind == AGGREGATED and sibling in session.readers:
                session.readers.pop(sibling).__del__()
        qos = BEST_EFFORT_QOS if topic_name in session.best_effort_topics else ROS_DEFAULT_QOS
        topic = Topic(session.participant, topic_name, DiagnosticArray, qos=ROS_DEFAULT_QOS)
        listener = Listener(on_data_available=self._on_data_callback(session, topic_name))  # type: ignore[no-untyped-call]
        session.readers[topic_name] = DataReader(session.subscriber, topic, qos=qos, listener=listener)
        how = " best-effort, as a writer of it is" if qos is BEST_EFFORT_QOS else ""
        log.info("reading %s on domain %d%s", topic_name, session.config.id, how)

    def _on_data_callback(self, session: _DomainSession, topic_name: str) -> Any:
        writers = session.writers

        def on_data_available(reader: DataReader[DiagnosticArray]) -> None:
            try:
                while True:
                    samples = ddspy_take(reader._ref, _ANY_SAMPLE, _TAKE_BATCH)
                    if isinstance(samples, int):
                        log.warning("take on %s failed with DDS error %d", topic_name, samples)
                        return
                    for data, info in samples:
                        if not info.valid_data:
                            continue
                        writer = writers.get(info.publication_handle)
                        ingest = None if writer is None else writer.ingest
                        if ingest is None:
                            ingest = self._hold(session, info.publication_handle, topic_name, data)
                        if ingest is not None:
                            take_sample(ingest, data, topic_name)
                    if len(samples) < _TAKE_BATCH:
                        return
            except Exception:  # a callback from the DDS thread must never raise
                log.exception("failed to process diagnostics from %s", topic_name)

        return on_data_available

    def _hold(self, session: _DomainSession, handle: int, topic: str, data: bytes) -> Ingest | None:
        """Keep a sample whose writer's robot is not known yet; its ingest when it became known meanwhile."""
        with self._lock:
            writer = session.writers.get(handle)
            if writer is None:  # data before its discovery sample was read
                writer = session.writers[handle] = _Writer(topic, "", b"", None, time.monotonic())
            if writer.ingest is not None or writer.ignored:
                return writer.ingest
            if len(writer.pending) < MAX_PENDING_SAMPLES:
                writer.pending.append(data)
            else:
                writer.pending[-1] = data  # the newest says the most
            return None


def _feed_name(writer: _Writer) -> str:
    """The feed a writer's samples are of in the model: one per writer of a topic."""
    return f"{writer.topic}@{writer.guid.hex()}"
