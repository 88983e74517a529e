"""The load generator's wire: Zenoh as rmw_zenoh publishes, and DDS by raw pre-serialized writes.

Zenoh, as `overseer.simulator.zenoh_publisher` publishes (ROS 2 Jazzy's rmw_zenoh): for each robot a
publisher on `<domain>/<ns>/diagnostics_agg/<type>/<hash>`, the liveliness tokens of its aggregator
node and of that publisher, and the 33-byte attachment, built once and patched in place with each
sample's sequence number and source timestamp. DDS: one loopback-only
Cyclone participant, one writer per robot topic `rt/<ns>/diagnostics_agg` with ROS 2's default QoS,
written the payload's bytes as they are (`ddspy_write`, as `testbed.dds_writer` does); or, as
diagnostic_updater publishes (`shared_topic`), every robot's writer on the absolute `rt/diagnostics`, the
ROS graph (`ros_discovery_info`) telling each writer's node, `/<ns>/diagnostic_updater`.

`publish` is the hot loop: for each robot of a range it patches the stamp into the robot's payload and
sends it. Both libraries copy the bytes before the call returns, so the next change can be made in
the same buffer at once.
"""

from __future__ import annotations

import json
import struct
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any, Protocol

import zenoh
from cyclonedds._clayer import ddspy_write
from cyclonedds.core import Policy, Qos
from cyclonedds.domain import DomainParticipant
from cyclonedds.pub import DataWriter, Publisher
from cyclonedds.topic import Topic
from cyclonedds.util import duration

from bench.loadgen_payloads import STAMP
from overseer.codec.discovery_info import TOPIC as GRAPH_TOPIC
from overseer.codec.discovery_info import NodeEntities, ParticipantEntities, encode_participant_entities
from overseer.simulator.zenoh_publisher import NODE_NAME, attachment
from overseer.sources.dds.cyclone_config import configure_domain, loopback_only_config
from overseer.sources.dds.source import ROS_DEFAULT_QOS
from overseer.sources.dds.types import DiagnosticArray as DdsDiagnosticArray
from overseer.sources.dds.types import ParticipantEntitiesInfo
from overseer.sources.topic_names import AGGREGATED, RAW, dds_topic_name
from overseer.sources.zenoh.keys import (
    DIAGNOSTIC_ARRAY_HASH,
    data_key,
    node_token,
    publisher_gid,
    publisher_token,
)

ZENOH = "zenoh"
DDS = "dds"
TRANSPORTS = (ZENOH, DDS)
UPDATER_NODE = "diagnostic_updater"  # the node each robot's writer of the shared topic belongs to
SESSION_TX_BATCHES = 16  # batches waiting on a session's link, as on the shipped router's (deploy/zenoh)
# Writes a sample's sequence number and source timestamp into an attachment: (buffer, 0, sequence, ns).
patch_attachment = struct.Struct("<qq").pack_into


class Wire(Protocol):
    """One transport's robots: opened, closed, published a range at a time."""

    failed: int  # samples the middleware refused

    def open(self, robot: int) -> None:
        """Declare robot `robot`'s publisher (and what announces it)."""

    def close(self, robot: int) -> None:
        """Undeclare robot `robot`'s publisher: the robot goes down."""

    def declared(self) -> None:
        """Announce what the `open` and `close` calls since the last call changed, where that is apart."""

    def publish(self, first: int, stop: int, payloads: Sequence[bytearray], stamp: bytes) -> int:
        """Send the payloads of the open robots from `first` to `stop` - 1, stamped; how many were sent."""

    def every_robot_subscribed(self) -> bool:
        """Whether every open robot's publisher has a matching subscriber."""

    def shut(self) -> None:
        """Close everything."""


@dataclass(frozen=True)
class ZenohEndpoints:
    """How the load generator's sessions reach the Zenoh network."""

    connect: tuple[str, ...] = ()
    listen: tuple[str, ...] = ()
    mode: str = "peer"  # rmw_zenoh's sessions are peers of the robot's router
    robots_per_session: int = 1000


def session_config(endpoints: ZenohEndpoints) -> zenoh.Config:
    """The configuration of each of the generator's Zenoh sessions."""
    native = zenoh.Config()
    native.insert_json5("mode", json.dumps(endpoints.mode))
    native.insert_json5("connect/endpoints", json.dumps(list(endpoints.connect)))
    native.insert_json5("listen/endpoints", json.dumps(list(endpoints.listen)))
    native.insert_json5("scouting/multicast/enabled", "false")
    # A session carries the traffic of a thousand robots' sessions: with Zenoh's 2 batches waiting, some of a
    # fleet's first publications, sent together at its start, were dropped there.
    native.insert_json5("transport/link/tx/queue/size/data", str(SESSION_TX_BATCHES))
    return native


class ZenohWire:
    """The fleet as rmw_zenoh publishes it, a session for every `robots_per_session` robots.

    One session per robot, as on real robots, would cost a process thousands of connections; one for
    the whole fleet would make declaring it slow (a session's declarations take time that grows with
    the number it holds, about 80 s for 10,000 robots' 30,000 against 3 s in sessions of 1,000).
    """

    def __init__(self, names: Sequence[str], domain: int, endpoints: ZenohEndpoints) -> None:
        """Open the sessions (in peer mode they need not reach anyone yet); no robot is declared."""
        native = session_config(endpoints)
        count = -(-len(names) // endpoints.robots_per_session)
        self.sessions = [zenoh.open(native) for _ in range(count)]  # robot i on session i // per session
        self._per_session = endpoints.robots_per_session
        self._names, self._domain = names, domain
        self._publishers: list[zenoh.Publisher | None] = [None] * len(names)
        self._puts: list[Callable[..., Any] | None] = [None] * len(names)
        self._tokens: list[list[zenoh.LivelinessToken]] = [[] for _ in names]
        self._attachments = [bytearray() for _ in names]
        self._sequences = [0] * len(names)
        self._entities = 0
        self.failed = 0

    def open(self, robot: int) -> None:
        """Declare the robot's publisher and the liveliness tokens of its node and of that publisher."""
        name, session = self._names[robot], self.sessions[robot // self._per_session]
        zid = str(session.zid())
        publisher = session.declare_publisher(data_key(self._domain, name, AGGREGATED))
        self._entities += 1
        token = publisher_token(
            self._domain, zid, self._entities, name, NODE_NAME, AGGREGATED, DIAGNOSTIC_ARRAY_HASH
        )
        liveliness = session.liveliness()
        self._tokens[robot] = [
            liveliness.declare_token(node_token(self._domain, zid, name, NODE_NAME)),
            liveliness.declare_token(token),
        ]
        self._attachments[robot] = bytearray(attachment(0, 0, publisher_gid(token)))
        self._publishers[robot], self._puts[robot] = publisher, publisher.put

    def close(self, robot: int) -> None:
        """Undeclare the robot's tokens and publisher, as a robot whose process ended."""
        publisher, self._publishers[robot], self._puts[robot] = self._publishers[robot], None, None
        for token in self._tokens[robot]:
            token.undeclare()  # type: ignore[no-untyped-call]
        self._tokens[robot] = []
        if publisher is not None:
            publisher.undeclare()  # type: ignore[no-untyped-call]

    def declared(self) -> None:
        """Nothing: each publisher's liveliness token announces it as it is declared."""

    def publish(self, first: int, stop: int, payloads: Sequence[bytearray], stamp: bytes) -> int:
        """Put each open robot's payload with its attachment's next sequence number and the time now."""
        timestamp = time.time_ns()
        puts, attachments, sequences = self._puts, self._attachments, self._sequences
        sent = 0
        for robot in range(first, stop):
            put = puts[robot]
            if put is None:
                continue
            sequence = sequences[robot] + 1
            sequences[robot] = sequence
            robot_attachment = attachments[robot]
            patch_attachment(robot_attachment, 0, sequence, timestamp)
            payload = payloads[robot]
            payload[STAMP] = stamp
            put(payload, attachment=robot_attachment)
            sent += 1
        return sent

    def every_robot_subscribed(self) -> bool:
        """Whether every declared publisher matches a subscriber."""
        return all(p.matching_status for p in self._publishers if p is not None)

    def shut(self) -> None:
        """Close the sessions, which undeclares every publisher and token."""
        for session in self.sessions:
            session.close()  # type: ignore[no-untyped-call]


class DdsWire:
    """The fleet as one loopback-only Cyclone participant with a raw writer per robot."""

    def __init__(self, names: Sequence[str], domain: int, shared_topic: bool = False) -> None:
        """Join `domain` on loopback only; no robot's writer is made yet.

        `shared_topic`: every robot writes `rt/diagnostics`, its node named in the ROS graph.
        """
        configure_domain(domain, loopback_only_config(), keep_existing=True)
        self._participant = DomainParticipant(domain)
        self._publisher = Publisher(self._participant)
        self._names = names
        self._topics: list[Topic[DdsDiagnosticArray] | None] = [None] * len(names)
        self._writers: list[DataWriter[DdsDiagnosticArray] | None] = [None] * len(names)
        self._refs: list[int | None] = [None] * len(names)
        self._shared: Topic[DdsDiagnosticArray] | None = None
        self._graph: DataWriter[ParticipantEntitiesInfo] | None = None
        if shared_topic:
            self._shared = Topic(
                self._participant, dds_topic_name("", RAW), DdsDiagnosticArray, qos=ROS_DEFAULT_QOS
            )
            graph_qos = Qos(
                Policy.Reliability.Reliable(duration(milliseconds=100)), Policy.Durability.TransientLocal
            )
            graph_topic = Topic(self._participant, GRAPH_TOPIC, ParticipantEntitiesInfo, qos=graph_qos)
            self._graph = DataWriter(self._participant, graph_topic, qos=graph_qos)
        self.failed = 0

    def open(self, robot: int) -> None:
        """Make the robot's writer (`rt/<ns>/diagnostics_agg` or the shared topic), ROS 2's default QoS."""
        topic = self._shared or self._topics[robot]
        if topic is None:
            topic_name = dds_topic_name(self._names[robot], AGGREGATED)
            topic = Topic(self._participant, topic_name, DdsDiagnosticArray, qos=ROS_DEFAULT_QOS)
            self._topics[robot] = topic
        writer = DataWriter(self._publisher, topic, qos=ROS_DEFAULT_QOS)
        self._writers[robot], self._refs[robot] = writer, writer._ref

    def close(self, robot: int) -> None:
        """Delete the robot's writer (its last reference), as a robot whose process ended."""
        self._writers[robot] = self._refs[robot] = None

    def declared(self) -> None:
        """With the shared topic, write the graph: each open robot's node and its writer."""
        if self._graph is None:
            return
        nodes = tuple(
            NodeEntities(f"/{name}", UPDATER_NODE, (writer.guid.bytes,))
            for name, writer in zip(self._names, self._writers, strict=True)
            if writer is not None
        )
        payload = encode_participant_entities(ParticipantEntities(self._participant.guid.bytes, nodes))
        if ddspy_write(self._graph._ref, payload + b"\x00" * (-len(payload) & 3)) < 0:
            self.failed += 1

    def publish(self, first: int, stop: int, payloads: Sequence[bytearray], stamp: bytes) -> int:
        """Write each open robot's payload as it is; refusals are counted in `failed`."""
        refs = self._refs
        sent = 0
        for robot in range(first, stop):
            ref = refs[robot]
            if ref is None:
                continue
            payload = payloads[robot]
            payload[STAMP] = stamp
            if ddspy_write(ref, payload) < 0:
                self.failed += 1
            else:
                sent += 1
        return sent

    def every_robot_subscribed(self) -> bool:
        """Whether every robot's writer has a matched reader."""
        return all(w.get_matched_subscriptions() for w in self._writers if w is not None)

    def shut(self) -> None:
        """Delete every writer, topic and the participant."""
        self._writers = [None] * len(self._names)
        self._refs = [None] * len(self._names)
        self._topics = [None] * len(self._names)
