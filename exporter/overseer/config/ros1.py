"""The `ros1:` section: ROS 1 robots by their masters, and how the exporter talks to them."""

from __future__ import annotations

import re
from dataclasses import dataclass, replace
from typing import Any

from overseer.config.errors import ConfigError
from overseer.config.options import Flag, Option, option
from overseer.config.parsers import listed, parse_duration, reject_unknown, string
from overseer.config.topics import DIAGNOSTIC_TOPICS
from overseer.ros_master import master_host


@dataclass(frozen=True)
class Ros1Robot:
    """A ROS 1 robot: its name and its master's XML-RPC URI."""

    name: str
    master_uri: str
    topic: str = "diagnostics_agg"


@dataclass(frozen=True)
class Ros1Config:
    """The ROS 1 transport: XML-RPC to each robot's master, TCPROS to its publishers."""

    robots: tuple[Ros1Robot, ...] = ()
    caller_id: str = "/overseer"
    advertise_host: str | None = None
    reconnect_min: float = 0.5
    reconnect_max: float = 30.0
    poll_interval: float = 5.0

    @property
    def enabled(self) -> bool:
        """True when any ROS 1 robot is configured."""
        return bool(self.robots)


def robots_from_flags(given: dict[str, Any]) -> list[dict[str, str]]:
    """ros1.robots from `--ros1.robot NAME=URI` and `--ros-master URI`; a bare NAME names the one master."""
    named, masters = given.get("--ros1.robot", []), given.get("--ros-master", [])
    robots = []
    names_for_master = []
    for text in named:
        name, sep, uri = text.partition("=")
        if sep:
            robots.append({"name": name, "master_uri": uri})
        elif len(masters) == 1 and name:
            names_for_master.append(name)
        else:
            raise ConfigError(
                "--ros1.robot: expected NAME=MASTER_URI (or NAME with exactly one --ros-master), "
                f"got {text!r}"
            )
    if len(names_for_master) > 1:
        raise ConfigError(f"--ros1.robot: one name for the one --ros-master, got {names_for_master}")
    for uri in masters:
        robots.append({"master_uri": uri, **({"name": names_for_master[0]} if names_for_master else {})})
    return robots


OPTIONS: tuple[Option, ...] = (
    Option(
        "ros1.robots",
        "none",
        "ROS 1 robots by their masters. --ros1.robot NAME=MASTER_URI names one "
        "(robot1=http://10.0.0.5:11311); --ros-master URL takes one named after its master's host "
        "(http://10.0.0.5:11311 is robot 10.0.0.5), and with one --ros-master a bare --ros1.robot NAME "
        "names it; both repeat. In the file: {name, master_uri, topic: diagnostics_agg or diagnostics}",
        (Flag("--ros1.robot", "repeated", "NAME=MASTER_URI"), Flag("--ros-master", "repeated", "URL")),
        from_flags=robots_from_flags,
    ),
    option(
        "ros1.caller_id", "/overseer", "the caller id the exporter registers with each master", metavar="ID"
    ),
    option(
        "ros1.advertise_host",
        "the address that reaches each master",
        "the host name or address publishers connect back to (the exporter's, as robots reach it)",
        metavar="HOST",
    ),
    option(
        "ros1.reconnect_min",
        "0.5s",
        "the first wait before reaching a master or publisher again",
        metavar="DURATION",
    ),
    option(
        "ros1.reconnect_max",
        "30s",
        "the longest wait between tries, doubling from reconnect_min",
        metavar="DURATION",
    ),
    option(
        "ros1.poll_interval",
        "5s",
        "how often each master is asked for the topic's publishers",
        metavar="DURATION",
    ),
)
KEYS = {entry.key.partition(".")[2] for entry in OPTIONS}


def ros1_config(raw: dict[str, Any]) -> Ros1Config:
    """The section from its mapping."""
    defaults = Ros1Config()
    robots = tuple(
        _ros1_robot(item, f"ros1.robots[{i}]")
        for i, item in enumerate(listed(raw.get("robots", []), "ros1.robots"))
    )
    names = [robot.name for robot in robots]
    if len(set(names)) != len(names):
        raise ConfigError(f"ros1.robots: robot names must be unique, got {names}")
    masters = [robot.master_uri.rstrip("/") for robot in robots]
    if len(set(masters)) != len(masters):
        # Two subscriptions with one caller id on one master keep shutting each other down.
        raise ConfigError(f"ros1.robots: each robot needs a master of its own, got {masters}")
    values: dict[str, Any] = {}
    for key in ("reconnect_min", "reconnect_max", "poll_interval"):
        if key in raw:
            values[key] = parse_duration(raw[key], f"ros1.{key}")
    for key in ("caller_id", "advertise_host"):
        if key in raw:
            values[key] = string(raw[key], f"ros1.{key}")
    config = replace(defaults, robots=robots, **values)
    if config.reconnect_max < config.reconnect_min:
        raise ConfigError(
            f"ros1.reconnect_max: must not be shorter than ros1.reconnect_min, got {config.reconnect_max:g}s"
        )
    return config


def _ros1_robot(item: object, key: str) -> Ros1Robot:
    if not isinstance(item, dict):
        raise ConfigError(f"{key}: expected a mapping with name and master_uri, got {item!r}")
    reject_unknown(item, key + ".", {"name", "master_uri", "topic"})
    master_uri = string(item.get("master_uri"), f"{key}.master_uri")
    if not re.fullmatch(r"https?://[^/\s:]+(:\d+)?/?", master_uri):
        raise ConfigError(f"{key}.master_uri: expected http://HOST:PORT, got {master_uri!r}")
    name = string(item["name"], f"{key}.name") if "name" in item else master_host(master_uri)
    topic = string(item.get("topic", "diagnostics_agg"), f"{key}.topic")
    if topic not in DIAGNOSTIC_TOPICS:
        raise ConfigError(f"{key}.topic: expected diagnostics_agg or diagnostics, got {topic!r}")
    return Ros1Robot(name, master_uri, topic)
