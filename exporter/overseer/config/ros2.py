"""The `ros2:` section: the exporter as a ROS 2 node (rclpy), reading robots and publishing the fleet."""

from __future__ import annotations

import re
from dataclasses import dataclass
from typing import Any

from overseer.config.errors import ConfigError
from overseer.config.options import Option, option
from overseer.config.parsers import boolean, listed, parse_duration, string, whole_number
from overseer.config.topics import DIAGNOSTIC_TOPICS

DEFAULT_FLEET_TOPIC = "/overseer/fleet_diagnostics"
# A ROS node name: letters, digits, underscores, not starting with a digit.
_NODE_NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")
# A fully qualified ROS topic name.
_TOPIC_NAME = re.compile(r"(/[A-Za-z_][A-Za-z0-9_]*)+")


@dataclass(frozen=True)
class Ros2Config:
    """The rclpy transport and the fleet's own DiagnosticArray; any RMW the installation has."""

    enabled: bool = False
    node_name: str = "overseer"
    domain: int = 0
    topics: tuple[str, ...] = DIAGNOSTIC_TOPICS
    prefer_aggregated: bool = True
    robot_name: str | None = None  # for `/diagnostics_agg` without a namespace (default "domain<N>")
    fleet_topic: str | None = DEFAULT_FLEET_TOPIC  # None: publish nothing
    fleet_period: float = 1.0

    @property
    def unnamespaced_robot(self) -> str:
        """The robot name for `/diagnostics_agg` without a namespace."""
        return self.robot_name or f"domain{self.domain}"


OPTIONS: tuple[Option, ...] = (
    option(
        "ros2.enabled",
        "off",
        "join the robots' ROS 2 graph as a node through rclpy (pip install overseer[ros2]); any ros2 key "
        "turns it on, and the DDS source is then off unless the configuration turns it on",
        kind="switch",
        flag="--ros2",
    ),
    option("ros2.node_name", "overseer", "the exporter's node name", metavar="NAME"),
    option("ros2.domain", "ROS_DOMAIN_ID, else 0", "the ROS domain to join", metavar="ID"),
    option(
        "ros2.topics",
        "diagnostics_agg, diagnostics",
        "a diagnostics topic to follow; repeat for both",
        kind="repeated",
        metavar="TOPIC",
        flag="--ros2.topic",
    ),
    option(
        "ros2.prefer_aggregated",
        "true",
        "read a robot that publishes both topics from diagnostics_agg only (true or false)",
        metavar="BOOL",
    ),
    option(
        "ros2.robot_name",
        "domain<ID>: robots by their nodes' namespaces",
        "name the domain's one robot: every un-namespaced topic is it, whatever its nodes' namespaces",
        metavar="NAME",
    ),
    option(
        "ros2.fleet_topic",
        DEFAULT_FLEET_TOPIC,
        "where the fleet's own DiagnosticArray is published, a status per robot (null in the file: nowhere)",
        metavar="TOPIC",
    ),
    option(
        "ros2.fleet_period", "1s", "how often the fleet's DiagnosticArray is published", metavar="DURATION"
    ),
)
KEYS = {entry.key.partition(".")[2] for entry in OPTIONS}


def ros2_config(raw: dict[str, Any]) -> Ros2Config:
    """The section from its mapping; any key of it turns the transport on, unless `enabled` says otherwise."""
    defaults = Ros2Config()
    node_name = string(raw.get("node_name", defaults.node_name), "ros2.node_name")
    if not _NODE_NAME.fullmatch(node_name):
        raise ConfigError(f"ros2.node_name: expected a ROS node name (letters, digits, _), got {node_name!r}")
    topics = defaults.topics
    if "topics" in raw:
        topics = tuple(string(t, "ros2.topics") for t in listed(raw["topics"], "ros2.topics"))
        for topic in topics:
            if topic not in DIAGNOSTIC_TOPICS:
                raise ConfigError(f"ros2.topics: expected diagnostics_agg or diagnostics, got {topic!r}")
    fleet_topic = raw.get("fleet_topic", defaults.fleet_topic)
    if fleet_topic is not None and not _TOPIC_NAME.fullmatch(string(fleet_topic, "ros2.fleet_topic")):
        raise ConfigError(
            f"ros2.fleet_topic: expected a topic name such as /overseer/fleet, got {fleet_topic!r}"
        )
    robot_name = raw.get("robot_name")
    return Ros2Config(
        enabled=boolean(raw.get("enabled", bool(raw)), "ros2.enabled"),
        node_name=node_name,
        domain=whole_number(raw.get("domain", defaults.domain), "ros2.domain", 0, 232, "a ROS domain id"),
        topics=topics,
        prefer_aggregated=boolean(
            raw.get("prefer_aggregated", defaults.prefer_aggregated), "ros2.prefer_aggregated"
        ),
        robot_name=None if robot_name is None else string(robot_name, "ros2.robot_name"),
        fleet_topic=fleet_topic,
        fleet_period=parse_duration(raw["fleet_period"], "ros2.fleet_period")
        if "fleet_period" in raw
        else defaults.fleet_period,
    )
