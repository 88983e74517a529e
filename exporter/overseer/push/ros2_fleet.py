"""The fleet back into ROS: one diagnostic_msgs/DiagnosticArray a period, a status per robot.

`rqt_robot_monitor` and Foxglove's diagnostics panels then show the whole fleet as one robot's
components: each robot's worst level (STALE while it is down), its name as `name` and `hardware_id`, a
message such as "2 error, 1 warn" or "down 12 s: no diagnostics", and its counts as key-values. It is
published from the exporter's node (`--ros2`) on `ros2.fleet_topic`, from the robots' summaries the API
serves, so it says what every other output says.
"""

from __future__ import annotations

import logging
from typing import Any

from diagnostic_msgs.msg import DiagnosticArray as RosDiagnosticArray
from rclpy.publisher import Publisher
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

from overseer.codec.cdr import encode_diagnostic_array
from overseer.config.ros2 import Ros2Config
from overseer.fleet.interface import Fleet, FleetPartUnavailable
from overseer.levels import Level
from overseer.messages import DiagnosticArray, DiagnosticStatus
from overseer.sources.ros2 import node as ros_node

log = logging.getLogger(__name__)

_COUNTED = (("error", "error"), ("warn", "warn"), ("stale", "stale"))


def robot_status(robot: dict[str, Any], now: float) -> DiagnosticStatus:
    """One robot's summary (an entry of GET /api/v1/robots) as a DiagnosticStatus."""
    name = robot["robot"]
    counts = robot["counts"]
    if robot["up"]:
        problems = [f"{counts[key]} {word}" for key, word in _COUNTED if counts[key]]
        message = ", ".join(problems) if problems else f"all {robot['components']} OK"
        level = Level(robot["level"])
    else:
        level = Level.STALE
        if not robot["publisher_alive"]:
            message = "down: its diagnostics publisher left"
        elif robot["last_message"] is None:
            message = "down: never heard from"
        else:
            message = f"down {max(0, round(now - robot['last_message']))} s: no diagnostics"
    values = (
        ("up", "true" if robot["up"] else "false"),
        ("components", str(robot["components"])),
        *((key, str(counts[key])) for key in ("ok", "warn", "error", "stale")),
        ("transport", robot["transport"]),
    )
    return DiagnosticStatus(int(level), name, message, name, values)


def fleet_array(document: dict[str, Any]) -> DiagnosticArray:
    """GET /api/v1/robots as one DiagnosticArray, stamped at its time."""
    now = float(document["generated_at"])
    seconds = int(now)
    statuses = tuple(robot_status(robot, now) for robot in document["robots"])
    return DiagnosticArray(seconds, int((now - seconds) * 1e9), "", statuses)


class FleetDiagnosticsPublisher:
    """Publishes `fleet` on `config.fleet_topic` every `config.fleet_period` from node `config.node_name`."""

    def __init__(self, config: Ros2Config, fleet: Fleet) -> None:
        """Publish `fleet` as `config` says, from `start` on."""
        self._config = config
        self._fleet = fleet
        self._ros: ros_node.RosNode | None = None
        self._publisher: Publisher | None = None
        self._task: int | None = None

    def start(self) -> None:
        """Join the graph (or share the node of this process's source) and publish every period."""
        ros = self._ros = ros_node.acquire(self._config.node_name, self._config.domain)
        ros.call(lambda: self._begin(ros))
        self._task = ros.every(self._config.fleet_period, self._publish)
        log.info("publishing the fleet's diagnostics on %s", self._config.fleet_topic)

    def stop(self) -> None:
        """Stop publishing and leave the graph."""
        ros, self._ros = self._ros, None
        if ros is not None:
            ros_node.leave(ros, self._end)

    def _begin(self, ros: ros_node.RosNode) -> None:
        assert self._config.fleet_topic is not None
        qos = QoSProfile(  # type: ignore[no-untyped-call]
            history=HistoryPolicy.KEEP_LAST,
            depth=1,
            reliability=ReliabilityPolicy.RELIABLE,
            durability=DurabilityPolicy.VOLATILE,
        )
        self._publisher = ros.node.create_publisher(RosDiagnosticArray, self._config.fleet_topic, qos)

    def _end(self, ros: ros_node.RosNode) -> None:
        if self._task is not None:
            ros.cancel(self._task)
        if self._publisher is not None:
            ros.node.destroy_publisher(self._publisher)

    def _publish(self) -> None:
        try:
            document = self._fleet.robots_document()
        except FleetPartUnavailable as error:  # a worker restarting: say nothing rather than half the fleet
            log.debug("fleet diagnostics not published: %s", error)
            return
        if self._publisher is not None:
            self._publisher.publish(encode_diagnostic_array(fleet_array(document)))
