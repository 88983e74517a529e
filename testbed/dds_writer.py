"""A hand-driven ROS 2 diagnostics publisher in the test process, for payloads the simulator never sends."""

from __future__ import annotations

import time
from collections.abc import Iterator
from contextlib import contextmanager

from cyclonedds._clayer import ddspy_write
from cyclonedds.core import Policy, Qos
from cyclonedds.domain import DomainParticipant
from cyclonedds.pub import DataWriter
from cyclonedds.topic import Topic
from cyclonedds.util import duration

from overseer.codec.discovery_info import (
    TOPIC,
    NodeEntities,
    ParticipantEntities,
    encode_participant_entities,
)
from overseer.sources.dds.cyclone_config import configure_domain, loopback_only_config
from overseer.sources.dds.source import BEST_EFFORT_QOS, ROS_DEFAULT_QOS
from overseer.sources.dds.types import DiagnosticArray, ParticipantEntitiesInfo


class RawDiagnosticsWriter:
    """Writes serialized payloads as they are onto one diagnostics topic."""

    def __init__(self, writer: DataWriter[DiagnosticArray]) -> None:
        """Wrap a Cyclone DDS writer of the ROS 2 DiagnosticArray type."""
        self._writer = writer

    @property
    def guid(self) -> bytes:
        """The writer's GUID, as the ROS graph lists it (16 bytes)."""
        return self._writer.guid.bytes

    def wait_for_reader(self, timeout: float = 30.0) -> None:
        """Wait until a reader has matched this writer: what is written before that is lost (volatile)."""
        deadline = time.monotonic() + timeout
        while not self._writer.get_matched_subscriptions():
            if time.monotonic() > deadline:
                raise TimeoutError(f"no reader matched the writer within {timeout}s")
            time.sleep(0.05)

    def write(self, payload: bytes) -> int:
        """Write one serialized sample; returns Cyclone's return code (negative when it refused it)."""
        padded = payload + b"\x00" * (-len(payload) & 3)
        result: int = ddspy_write(self._writer._ref, padded)
        return result


_participants: dict[int, DomainParticipant] = {}


def _participant(domain_id: int) -> DomainParticipant:
    if domain_id not in _participants:
        configure_domain(domain_id, loopback_only_config())
        _participants[domain_id] = DomainParticipant(domain_id)
    return _participants[domain_id]


@contextmanager
def raw_diagnostics_writer(
    domain_id: int, dds_topic: str, best_effort: bool = False
) -> Iterator[RawDiagnosticsWriter]:
    """A loopback-only writer on `dds_topic` in `domain_id` (reliable, or best-effort), deleted at the end."""
    participant = _participant(domain_id)
    topic = Topic(participant, dds_topic, DiagnosticArray, qos=ROS_DEFAULT_QOS)
    writer = DataWriter(participant, topic, qos=BEST_EFFORT_QOS if best_effort else ROS_DEFAULT_QOS)
    try:
        yield RawDiagnosticsWriter(writer)
    finally:
        del writer, topic


class RosGraphWriter:
    """Announces on `ros_discovery_info`, as an rmw does, that nodes own some writers."""

    def __init__(self, participant: DomainParticipant, writer: DataWriter[ParticipantEntitiesInfo]) -> None:
        """Write `participant`'s graph through `writer`."""
        self._gid = participant.guid.bytes
        self._writer = writer

    def announce(self, *nodes: NodeEntities) -> None:
        """Say that the participant's nodes are now `nodes` (with their writers' GUIDs)."""
        payload = encode_participant_entities(ParticipantEntities(self._gid, nodes))
        result = ddspy_write(self._writer._ref, payload + b"\x00" * (-len(payload) & 3))
        if result < 0:
            raise RuntimeError(f"writing the graph failed with DDS error {result}")


@contextmanager
def ros_graph_writer(domain_id: int) -> Iterator[RosGraphWriter]:
    """A loopback-only `ros_discovery_info` writer (reliable, transient-local), deleted at the end."""
    participant = _participant(domain_id)
    qos = Qos(Policy.Reliability.Reliable(duration(milliseconds=100)), Policy.Durability.TransientLocal)
    topic = Topic(participant, TOPIC, ParticipantEntitiesInfo, qos=qos)
    writer = DataWriter(participant, topic, qos=qos)
    try:
        yield RosGraphWriter(participant, writer)
    finally:
        del writer, topic
