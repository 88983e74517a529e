"""Which ROS 2 node each DDS writer belongs to, read from the graph every rmw publishes.

Every ROS 2 process's participant publishes, on `ros_discovery_info` (reliable, transient-local), its nodes
with their namespaces and the GUIDs of their writers (`codec.discovery_info`). A sample of a diagnostics
topic names its writer (its publication handle, and through the built-in topic its GUID), so the node, and
so the robot, that published it. A participant's latest sample replaces what it said before; one that
leaves cleanly says it has no nodes left. Bounded: a flood of participants or writers is cut off.
"""

from __future__ import annotations

import logging
from typing import NamedTuple

from cyclonedds._clayer import ddspy_take
from cyclonedds.core import InstanceState, Policy, Qos, SampleState, ViewState
from cyclonedds.domain import DomainParticipant
from cyclonedds.sub import DataReader, Subscriber
from cyclonedds.topic import Topic
from cyclonedds.util import duration

from overseer.codec import DecodeError
from overseer.codec.discovery_info import TOPIC, decode_participant_entities
from overseer.sources.dds.types import ParticipantEntitiesInfo

log = logging.getLogger(__name__)

MAX_PARTICIPANTS = 20_000
MAX_WRITERS_PER_PARTICIPANT = 10_000
_TAKE_BATCH = 256
_ANY_SAMPLE = SampleState.Any | ViewState.Any | InstanceState.Any
# As rmw_dds_common publishes it; the reader keeps more than one sample: the topic has no key, so every
# participant's sample is of one instance.
_QOS = Qos(
    Policy.Reliability.Reliable(duration(milliseconds=100)),
    Policy.Durability.TransientLocal,
    Policy.History.KeepLast(1024),
)


class Node(NamedTuple):
    """A ROS 2 node: its namespace (`/` for none) and its name."""

    namespace: str
    name: str


class NodeGraph:
    """The writers of a DDS domain's ROS 2 nodes, from `ros_discovery_info`."""

    def __init__(self, participant: DomainParticipant, subscriber: Subscriber) -> None:
        """Read the graph of `participant`'s domain through `subscriber`."""
        topic = Topic(participant, TOPIC, ParticipantEntitiesInfo, qos=_QOS)
        self._reader: DataReader[ParticipantEntitiesInfo] = DataReader(subscriber, topic, qos=_QOS)
        self._participants: dict[bytes, tuple[bytes, ...]] = {}  # participant → the writers it listed
        self._writers: dict[bytes, Node] = {}
        self.malformed = 0

    def poll(self) -> bool:
        """Read what arrived since the last poll; True when some writer's node became known or changed."""
        changed = False
        while True:
            samples = ddspy_take(self._reader._ref, _ANY_SAMPLE, _TAKE_BATCH)
            if isinstance(samples, int):
                log.warning("take on %s failed with DDS error %d", TOPIC, samples)
                return changed
            for data, info in samples:
                if info.valid_data:
                    changed |= self._update(data)
            if len(samples) < _TAKE_BATCH:
                return changed

    def node_of(self, writer: bytes) -> Node | None:
        """The node whose writer has GUID `writer`, when its participant has said so."""
        return self._writers.get(writer)

    def _update(self, payload: bytes) -> bool:
        try:
            participant = decode_participant_entities(payload)
        except DecodeError as error:
            self.malformed += 1
            log.debug("malformed %s sample: %s", TOPIC, error)
            return False
        if participant.gid not in self._participants and len(self._participants) >= MAX_PARTICIPANTS:
            return False
        for writer in self._participants.pop(participant.gid, ()):
            self._writers.pop(writer, None)
        listed: list[bytes] = []
        for node in participant.nodes:
            for writer in node.writers[: MAX_WRITERS_PER_PARTICIPANT - len(listed)]:
                self._writers[writer] = Node(node.namespace, node.name)
                listed.append(writer)
        if listed:
            self._participants[participant.gid] = tuple(listed)
        return bool(listed)
