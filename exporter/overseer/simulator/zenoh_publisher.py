"""The fleet simulator over Zenoh: each virtual robot publishes as rmw_zenoh does, or as the bridge does.

As rmw_zenoh (ROS 2 Jazzy): `<domain>/<ns>/diagnostics_agg/diagnostic_msgs::msg::dds_::DiagnosticArray_/
RIHS01_…`, with the attachment rmw_zenoh sends (sequence number and source timestamp as int64, then the
publisher's GID, the XXH3-128 hash of its liveliness token, as a sequence of 16 bytes, in zenoh-ext
serialization) and the liveliness tokens of the node and of the publisher. As
zenoh-bridge-ros2dds: `<ns>/diagnostics_agg`, no attachment, and the bridge's token for the route.
The payload is the same CDR sample the DDS simulator writes; the fleet's design, events and timing
are shared with it.
"""

from __future__ import annotations

import json
import struct
import time
from dataclasses import dataclass, field

import zenoh

from overseer.simulator.publisher import FleetSimulator, SimulatedRobot, SimulatorSettings
from overseer.sources.zenoh.keys import (
    DIAGNOSTIC_ARRAY_HASH,
    bridge_key,
    bridge_publisher_token,
    data_key,
    node_token,
    publisher_gid,
    publisher_token,
)

NODE_NAME = "diagnostic_aggregator"
_I64 = struct.Struct("<q")


@dataclass(frozen=True)
class ZenohSettings:
    """How the simulated robots reach the Zenoh network and which key format they publish."""

    connect: tuple[str, ...] = ()
    listen: tuple[str, ...] = ()
    mode: str = "peer"  # rmw_zenoh's sessions are peers of the robot's router
    bridge_keys: bool = False
    type_hash: str = DIAGNOSTIC_ARRAY_HASH
    multicast_scouting: bool = False


@dataclass
class _Writer:
    """One robot's Zenoh publisher, its liveliness tokens and the attachment's state."""

    publisher: zenoh.Publisher
    tokens: list[zenoh.LivelinessToken] = field(default_factory=list)
    gid: bytes = b""
    sequence: int = 0


def attachment(sequence_number: int, source_timestamp: int, source_gid: bytes) -> bytes:
    """rmw_zenoh's attachment (33 bytes): int64 sequence number and timestamp, and the 16-byte GID."""
    return b"".join(
        [
            _I64.pack(sequence_number),
            _I64.pack(source_timestamp),
            bytes([len(source_gid)]),  # a sequence length (LEB128; one byte below 128)
            source_gid,
        ]
    )


class ZenohFleetSimulator(FleetSimulator):
    """Publishes the virtual fleet over one Zenoh session instead of DDS."""

    def __init__(self, settings: SimulatorSettings, zenoh_settings: ZenohSettings) -> None:
        """Build the fleet; the session opens at once (in peer mode it need not reach anyone yet)."""
        super().__init__(settings)
        self.zenoh_settings = zenoh_settings
        native = zenoh.Config()
        native.insert_json5("mode", json.dumps(zenoh_settings.mode))
        native.insert_json5("connect/endpoints", json.dumps(list(zenoh_settings.connect)))
        native.insert_json5("listen/endpoints", json.dumps(list(zenoh_settings.listen)))
        native.insert_json5("scouting/multicast/enabled", json.dumps(zenoh_settings.multicast_scouting))
        self._session = zenoh.open(native)
        self._zid = str(self._session.zid())
        self._zenoh_writers: dict[str, _Writer] = {}
        self._entities = 0

    def robot_key(self, robot: SimulatedRobot) -> str:
        """The key the robot publishes on."""
        namespace = "" if self.settings.separate_domains else robot.name
        if self.zenoh_settings.bridge_keys:
            return bridge_key(namespace, self.settings.topic)
        return data_key(robot.domain, namespace, self.settings.topic, self.zenoh_settings.type_hash)

    def publish_once(self) -> int:
        """Publish every running robot's diagnostics once; returns the number of messages written."""
        now, stamp = self.stamp_now()
        written = 0
        for robot in self.paced_robots():
            writer = self._zenoh_writers.get(robot.name)
            if writer is None:
                continue
            payload = self.payload(robot, now, stamp)
            if self.zenoh_settings.bridge_keys:
                writer.publisher.put(payload)
            else:
                writer.sequence += 1
                writer.publisher.put(
                    payload, attachment=attachment(writer.sequence, time.time_ns(), writer.gid)
                )
            written += 1
        self.published += written
        return written

    def every_robot_subscribed(self) -> bool:
        """Whether every robot's publisher has a matching subscriber."""
        return all(writer.publisher.matching_status for writer in self._zenoh_writers.values())

    def close(self) -> None:
        """Undeclare every publisher and token and close the session."""
        for robot in self.robots:
            self._close_writer(robot)
        self._session.close()  # type: ignore[no-untyped-call]

    def _open_writer(self, robot: SimulatedRobot) -> None:
        if not robot.running or robot.name in self._zenoh_writers:
            return
        publisher = self._session.declare_publisher(self.robot_key(robot))
        writer = _Writer(publisher)
        namespace = "" if self.settings.separate_domains else robot.name
        liveliness = self._session.liveliness()
        if self.zenoh_settings.bridge_keys:
            token = bridge_publisher_token(self._zid, namespace, self.settings.topic)
            writer.tokens.append(liveliness.declare_token(token))
        else:
            self._entities += 1
            token = publisher_token(
                robot.domain,
                self._zid,
                self._entities,
                namespace,
                NODE_NAME,
                self.settings.topic,
                self.zenoh_settings.type_hash,
            )
            writer.tokens.append(
                liveliness.declare_token(node_token(robot.domain, self._zid, namespace, NODE_NAME))
            )
            writer.tokens.append(liveliness.declare_token(token))
            writer.gid = publisher_gid(token)
        self._zenoh_writers[robot.name] = writer

    def _close_writer(self, robot: SimulatedRobot) -> None:
        writer = self._zenoh_writers.pop(robot.name, None)
        if writer is None:
            return
        for token in writer.tokens:
            token.undeclare()  # type: ignore[no-untyped-call]
        writer.publisher.undeclare()  # type: ignore[no-untyped-call]
