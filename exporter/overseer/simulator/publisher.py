"""The fleet simulator: the paper's virtual robots, publishing real ROS 2 diagnostics over DDS.

Each robot publishes `/robotI/diagnostics_agg` (DDS topic `rt/robotI/diagnostics_agg`) at a fixed rate,
as a robot's diagnostic aggregator would, with ROS 2 type names and default QoS, so any ROS 2 tool or
exporter sees it as a robot. Scripted events change a component's level, silence a component, or stop
and restart a robot at given times, for tests and demos.
"""

from __future__ import annotations

import logging
import os
import struct
import threading
import time
from collections.abc import Iterator
from dataclasses import dataclass, field

from cyclonedds._clayer import ddspy_write
from cyclonedds.domain import DomainParticipant
from cyclonedds.pub import DataWriter, Publisher
from cyclonedds.topic import Topic

from overseer.codec.cdr import encode_diagnostic_array
from overseer.config.dds import DEFAULT_MAX_PARTICIPANT_INDEX, DdsPeer
from overseer.levels import Level
from overseer.messages import DiagnosticArray, DiagnosticStatus
from overseer.simulator.design import LeafComponent, aggregated_statuses, initial_levels, leaf_components
from overseer.sources.dds.cyclone_config import (
    LOOPBACK_MAX_PARTICIPANTS,
    configure_domain,
    loopback_only_config,
    peers_config,
)
from overseer.sources.dds.peers import peer_addresses
from overseer.sources.dds.source import ROS_DEFAULT_QOS
from overseer.sources.dds.types import DiagnosticArray as DdsDiagnosticArray
from overseer.sources.topic_names import AGGREGATED, dds_topic_name

log = logging.getLogger(__name__)

_STAMP = struct.Struct("<iI")
SPREAD = 0.8  # share of the period over which one round of paced publications is spread
_PACE_EVERY = 20  # robots published between two pauses
ROBOT_ACTIONS = ("stop", "start")
COMPONENT_ACTIONS = ("silence", "resume")


VARYING_COMPONENT = "/Power/Robot Battery"  # leaf 0: every simulated robot has it
VARYING_PLACEHOLDER = "VVVVVVVV"


VARY_VALUES = ("none", "battery", "all")
VARYING_KEY = "reading"  # the key-value every status carries with --vary-values all


def _with_varying_voltage(status: DiagnosticStatus) -> DiagnosticStatus:
    values = tuple((k, VARYING_PLACEHOLDER if k == "voltage" else v) for k, v in status.values)
    return status._replace(values=values)


def _with_varying_reading(status: DiagnosticStatus) -> DiagnosticStatus:
    return status._replace(values=(*status.values, (VARYING_KEY, VARYING_PLACEHOLDER)))


def _offsets(data: bytearray, needle: bytes) -> list[int]:
    """Where `needle` starts in `data`, every time."""
    found, start = [], data.find(needle)
    while start >= 0:
        found.append(start)
        start = data.find(needle, start + len(needle))
    return found


class EventError(ValueError):
    """A scripted event that cannot be understood."""


@dataclass(frozen=True)
class Event:
    """A scripted change: at `at` seconds, `action` on `robot` (and `component`, for level changes)."""

    at: float
    robot: str
    action: str
    component: str | None = None


def parse_event(text: str) -> Event:
    """Parse `T:ROBOT:stop|start` or `T:ROBOT:COMPONENT:OK|WARN|ERROR|STALE|silence|resume`."""
    parts = text.split(":")
    if len(parts) < 3:
        raise EventError(f"event {text!r}: expected T:ROBOT:ACTION or T:ROBOT:COMPONENT:ACTION")
    try:
        at = float(parts[0])
    except ValueError:
        raise EventError(f"event {text!r}: time {parts[0]!r} is not a number of seconds") from None
    if len(parts) == 3:
        if parts[2] not in ROBOT_ACTIONS:
            raise EventError(f"event {text!r}: robot action must be stop or start")
        return Event(at, parts[1], parts[2])
    component, action = ":".join(parts[2:-1]), parts[-1]
    if action not in COMPONENT_ACTIONS and action not in Level.__members__:
        raise EventError(f"event {text!r}: action must be OK, WARN, ERROR, STALE, silence or resume")
    return Event(at, parts[1], action, component)


@dataclass
class SimulatedRobot:
    """One virtual robot's state and its DDS writer."""

    name: str
    domain: int
    levels: dict[str, Level]
    silenced: set[str] = field(default_factory=set)
    running: bool = True
    payload_tail: bytearray | None = None  # the encoded array after its stamp, rebuilt when state changes
    varying_at: list[int] = field(
        default_factory=list
    )  # offsets in payload_tail of values rewritten each time


@dataclass
class SimulatorSettings:
    """What to simulate."""

    robots: int = 3
    components: int = 10
    warn: int = 1
    error: int = 1
    rate: float = 1.0
    domain: int = 0
    separate_domains: bool = False
    namespace_prefix: str = "robot"
    topic: str = AGGREGATED
    loopback_only: bool = False
    peers: tuple[DdsPeer, ...] = ()  # hosts to announce the robots to directly, e.g. the exporter's
    vary_values: str = (
        "none"  # "battery": one voltage per robot changes at every publication; "all": every status
    )
    wait_for_subscribers: float = 0.0  # seconds to wait until every writer has a matched reader
    subscribers: int = 1  # how many readers each writer waits for (several exporters compared)
    events: list[Event] = field(default_factory=list)


class FleetSimulator:
    """Publishes a virtual fleet's diagnostics and plays its scripted events."""

    def __init__(self, settings: SimulatorSettings) -> None:
        """Build the fleet described by `settings`; nothing is published until `run`."""
        self.settings = settings
        self.leaves: list[LeafComponent] = leaf_components(settings.components)
        levels = initial_levels(self.leaves, settings.warn, settings.error)
        self.robots = [
            SimulatedRobot(
                self.robot_name(i),
                settings.domain + i if settings.separate_domains else settings.domain,
                dict(levels),
            )
            for i in range(settings.robots)
        ]
        names = {robot.name for robot in self.robots}
        leaf_names = {leaf.name for leaf in self.leaves}
        for event in settings.events:
            if event.robot not in names:
                raise EventError(f"event for unknown robot {event.robot!r}")
            if event.component is not None and event.component not in leaf_names:
                raise EventError(f"event for unknown component {event.component!r}")
        self._participants: dict[int, DomainParticipant] = {}
        self._writers: dict[str, DataWriter[DdsDiagnosticArray]] = {}
        self._stop = threading.Event()
        self.published = 0

    def robot_name(self, index: int) -> str:
        """The name of the robot at `index` (robot1 … robotN); its namespace unless on separate domains."""
        return f"{self.settings.namespace_prefix}{index + 1}"

    def topic_name(self, robot: SimulatedRobot) -> str:
        """The DDS topic the robot publishes on."""
        namespace = "" if self.settings.separate_domains else robot.name
        return dds_topic_name(namespace, self.settings.topic)

    def run(self, duration: float | None = None) -> None:
        """Publish at the configured rate until `stop` is called or `duration` seconds pass."""
        started = time.monotonic()
        pending = sorted(self.settings.events, key=lambda e: e.at)
        period = 1.0 / self.settings.rate
        tick = 0
        for robot in self.robots:
            self._open_writer(robot)
        if self.settings.wait_for_subscribers:
            self.wait_for_subscribers(self.settings.wait_for_subscribers)
            started = time.monotonic()
        while not self._stop.is_set():
            elapsed = time.monotonic() - started
            if duration is not None and elapsed >= duration:
                break
            while pending and pending[0].at <= elapsed:
                self._play(pending.pop(0))
            self.publish_once()
            tick += 1
            self._stop.wait(max(0.0, started + tick * period - time.monotonic()))
        self.close()

    def wait_for_subscribers(self, timeout: float) -> bool:
        """Wait until `every_robot_subscribed`; False when `timeout` passed first."""
        deadline = time.monotonic() + timeout
        while not self._stop.is_set() and time.monotonic() < deadline:
            if self.every_robot_subscribed():
                return True
            self._stop.wait(0.1)
        log.warning("not every robot has a subscriber after %gs; publishing anyway", timeout)
        return False

    def every_robot_subscribed(self) -> bool:
        """Whether every robot's writer has `settings.subscribers` matched readers."""
        wanted = self.settings.subscribers
        return all(len(writer.get_matched_subscriptions()) >= wanted for writer in self._writers.values())

    def stop(self) -> None:
        """Ask `run` to return."""
        self._stop.set()

    def publish_once(self) -> int:
        """Publish every running robot's diagnostics once; returns the number of messages written."""
        now, stamp = self.stamp_now()
        written = 0
        for robot in self.robots:
            writer = self._writers.get(robot.name)
            if writer is None:
                continue
            result = ddspy_write(writer._ref, self.payload(robot, now, stamp))
            if result < 0:
                log.warning("writing %s failed with DDS error %d", robot.name, result)
            else:
                written += 1
        self.published += written
        return written

    def paced_robots(self) -> Iterator[SimulatedRobot]:
        """The robots in order, spread over most of one period.

        Real robots are not in step, and one process standing in for a fleet through one session (Zenoh,
        rclpy) would overflow its queue if it published them all in one burst.
        """
        started, spread, count = time.monotonic(), SPREAD / self.settings.rate, len(self.robots)
        for index, robot in enumerate(self.robots):
            if index % _PACE_EVERY == 0 and index:
                self._stop.wait(max(0.0, started + spread * index / count - time.monotonic()))
            yield robot

    @staticmethod
    def stamp_now() -> tuple[float, bytes]:
        """Now, and now as a message header's stamp (seconds, nanoseconds)."""
        now = time.time()
        return now, _STAMP.pack(int(now), int((now % 1) * 1e9))

    def payload(self, robot: SimulatedRobot, now: float, stamp: bytes) -> bytes:
        """The robot's serialized array (CDR with its header) stamped `stamp`, varied for `now` if asked."""
        if robot.payload_tail is None:
            robot.payload_tail = bytearray(self.encode(robot)[12:])
            robot.varying_at = _offsets(robot.payload_tail, VARYING_PLACEHOLDER.encode())
        if robot.varying_at:
            # Values that change at every publication, as real ones do, without re-encoding.
            reading = f"{12.0 + (now * 7.3 % 1.0):0{len(VARYING_PLACEHOLDER)}.5f}".encode()
            tail, width = robot.payload_tail, len(reading)
            for offset in robot.varying_at:
                tail[offset : offset + width] = reading
        return b"\x00\x01\x00\x00" + stamp + bytes(robot.payload_tail)

    def encode(self, robot: SimulatedRobot) -> bytes:
        """The robot's current DiagnosticArray as little-endian CDR, padded to whole words."""
        statuses = aggregated_statuses(self.leaves, robot.levels, robot.silenced)
        if self.settings.vary_values == "battery":
            statuses = [
                _with_varying_voltage(status) if status.name == VARYING_COMPONENT else status
                for status in statuses
            ]
        elif self.settings.vary_values == "all":
            statuses = [_with_varying_reading(status) for status in statuses]
        payload = encode_diagnostic_array(DiagnosticArray(0, 0, "", tuple(statuses)))
        return payload + b"\x00" * (-len(payload) & 3)

    def close(self) -> None:
        """Delete every writer and participant."""
        self._writers.clear()
        self._participants.clear()

    def _play(self, event: Event) -> None:
        robot = next(r for r in self.robots if r.name == event.robot)
        log.info("event at %.1fs: %s %s %s", event.at, event.robot, event.component or "", event.action)
        if event.action == "stop":
            robot.running = False
            self._close_writer(robot)
        elif event.action == "start":
            robot.running = True
            self._open_writer(robot)
        elif event.component is not None:
            if event.action == "silence":
                robot.silenced.add(event.component)
            elif event.action == "resume":
                robot.silenced.discard(event.component)
            else:
                robot.levels[event.component] = Level[event.action]
            robot.payload_tail = None

    def _close_writer(self, robot: SimulatedRobot) -> None:
        self._writers.pop(robot.name, None)

    def _open_writer(self, robot: SimulatedRobot) -> None:
        if not robot.running or robot.name in self._writers:
            return
        participant = self._participant(robot.domain)
        topic = Topic(participant, self.topic_name(robot), DdsDiagnosticArray, qos=ROS_DEFAULT_QOS)
        self._writers[robot.name] = DataWriter(Publisher(participant), topic, qos=ROS_DEFAULT_QOS)

    def _participant(self, domain_id: int) -> DomainParticipant:
        if domain_id not in self._participants:
            if self.settings.loopback_only or self.settings.peers:
                configure_domain(domain_id, self._cyclone_config(), keep_existing=True)
            self._participants[domain_id] = DomainParticipant(domain_id)
        return self._participants[domain_id]

    def _cyclone_config(self) -> str:
        loopback = self.settings.loopback_only
        base = loopback_only_config() if loopback else os.environ.get("CYCLONEDDS_URI", "")
        addresses = peer_addresses(
            self.settings.peers, lambda peer, error: log.warning("DDS peer %s left out: %s", peer, error)
        )
        max_index = LOOPBACK_MAX_PARTICIPANTS if loopback else DEFAULT_MAX_PARTICIPANT_INDEX
        return ",".join(fragment for fragment in (base, peers_config(addresses, max_index)) if fragment)
