"""The `fleet:` section (the model's time limits, caps, and how robots are named) and `shard`."""

from __future__ import annotations

import contextlib
import re
from dataclasses import fields
from typing import Any

from overseer.config.errors import ConfigError
from overseer.config.options import Option, file_only, option
from overseer.config.parsers import (
    FlagText,
    listed,
    parse_duration,
    positive_integer,
    reject_unknown,
    string,
    whole_number,
)
from overseer.model import FleetLimits
from overseer.model.shard import Shard
from overseer.model.state import StaleOverride

DEFAULT_NAMESPACE_DEPTH = 1  # /robot_a/drivers/lidar is robot robot_a
MAX_NAMESPACE_DEPTH = 32
NAMESPACE_DEPTH_KEY = "robot_namespace_depth"
_DURATIONS = ("stale_after", "robot_timeout", "expire_after")
OPTIONS: tuple[Option, ...] = (
    option(
        "fleet.stale_after",
        "5s",
        "a component not updated for this long (or three of its producer's periods, when longer) is STALE; "
        "5s is the ROS aggregator's and Foxglove's default",
        metavar="DURATION",
    ),
    option(
        "fleet.robot_timeout",
        "10s",
        "a robot silent for this long (or three of its own periods, when longer) is down; not shorter "
        "than stale_after",
        metavar="DURATION",
    ),
    option(
        "fleet.expire_after",
        "7d",
        "a robot not in the inventory, or a component it does not expect, silent for this long is forgotten "
        "(an event says so); not shorter than robot_timeout",
        metavar="DURATION",
    ),
    option(
        "fleet.stale_periods",
        "3",
        "a slower producer's components are STALE after this many of its learned periods (1 to 100)",
        metavar="N",
    ),
    file_only(
        "fleet.stale_overrides",
        "none",
        "components whose whole name matches a regular expression are STALE after exactly this long: "
        "[{match: 'NTP offset.*', stale_after: 60s}], the first that matches",
        "a list of mappings",
    ),
    option(
        "fleet.robot_namespace_depth",
        str(DEFAULT_NAMESPACE_DEPTH),
        "leading segments of a node's namespace that name its robot, for un-namespaced topics "
        "(/robot_a/drivers is robot_a; 0: the whole namespace)",
        metavar="N",
    ),
    option("fleet.max_robots", "10000", "robots beyond this are dropped and counted", metavar="N"),
    option(
        "fleet.max_components_per_robot",
        "1000",
        "a robot's components beyond this are dropped and counted",
        metavar="N",
    ),
    option(
        "fleet.max_feeds_per_robot",
        "64",
        "publishers heard per robot; messages of more are dropped and counted",
        metavar="N",
    ),
    option(
        "fleet.max_values_per_component",
        "64",
        "a status's key-values beyond this are dropped and counted",
        metavar="N",
    ),
    option(
        "fleet.max_string_length",
        "1024",
        "longer names, messages and key-values are cut, and counted",
        metavar="N",
    ),
)
KEYS = {entry.key.partition(".")[2] for entry in OPTIONS}


def fleet_limits(raw: dict[str, Any]) -> FleetLimits:
    """The section from its mapping: durations, positive caps, overrides, and timeouts in their order."""
    values: dict[str, Any] = {}
    for f in fields(FleetLimits):
        if f.name not in raw:
            continue
        key = f"fleet.{f.name}"
        if f.name.startswith("max_"):
            values[f.name] = positive_integer(raw[f.name], key)
        elif f.name in _DURATIONS:
            values[f.name] = parse_duration(raw[f.name], key)
        elif f.name == "stale_periods":
            values[f.name] = _stale_periods(raw[f.name])
        elif f.name == "stale_overrides":
            values[f.name] = stale_overrides(raw[f.name])
    limits = FleetLimits(**values)
    if limits.robot_timeout < limits.stale_after:
        raise ConfigError(
            f"fleet.robot_timeout: must not be shorter than fleet.stale_after ({limits.stale_after:g}s), "
            f"got {limits.robot_timeout:g}s"
        )
    if limits.expire_after < limits.robot_timeout:
        raise ConfigError(
            f"fleet.expire_after: must not be shorter than fleet.robot_timeout ({limits.robot_timeout:g}s), "
            f"got {limits.expire_after:g}s"
        )
    return limits


def robot_namespace_depth(raw: dict[str, Any]) -> int:
    """`fleet.robot_namespace_depth`: how many leading segments of a node's namespace name its robot."""
    if NAMESPACE_DEPTH_KEY not in raw:
        return DEFAULT_NAMESPACE_DEPTH
    return whole_number(raw[NAMESPACE_DEPTH_KEY], f"fleet.{NAMESPACE_DEPTH_KEY}", 0, MAX_NAMESPACE_DEPTH)


def stale_overrides(value: object) -> tuple[StaleOverride, ...]:
    """`fleet.stale_overrides`: a list of `{match: <regular expression>, stale_after: <duration>}`."""
    overrides = []
    for index, item in enumerate(listed(value, "fleet.stale_overrides")):
        key = f"fleet.stale_overrides[{index}]"
        if not isinstance(item, dict):
            raise ConfigError(f"{key}: expected a mapping with match and stale_after, got {item!r}")
        reject_unknown(item, key + ".", {"match", "stale_after"})
        if "match" not in item or "stale_after" not in item:
            raise ConfigError(f"{key}: expected both match and stale_after, got {sorted(item)}")
        pattern = string(item["match"], f"{key}.match")
        try:
            compiled = re.compile(pattern)
        except re.error as error:
            raise ConfigError(f"{key}.match: {pattern!r} is not a regular expression: {error}") from None
        overrides.append(StaleOverride(compiled, parse_duration(item["stale_after"], f"{key}.stale_after")))
    return tuple(overrides)


def _stale_periods(value: object) -> float:
    number = value
    if isinstance(value, FlagText):
        with contextlib.suppress(ValueError):
            number = float(value)
    if isinstance(number, bool) or not isinstance(number, int | float) or not 1 <= number <= 100:
        raise ConfigError(f"fleet.stale_periods: expected a number from 1 to 100, got {value!r}")
    return float(number)


def parse_shard(value: object, key: str = "shard") -> Shard:
    """A `Shard` from `i/n` with 0 <= i < n."""
    match = re.fullmatch(r"(\d+)/(\d+)", value) if isinstance(value, str) else None
    if match is None or not 0 <= int(match.group(1)) < int(match.group(2)):
        raise ConfigError(f"{key}: expected i/n with 0 <= i < n, such as 0/2, got {value!r}")
    return Shard(int(match.group(1)), int(match.group(2)))
