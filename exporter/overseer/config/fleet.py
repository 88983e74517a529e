"""The `fleet:` section (the model's time limits and caps) and `shard`, this exporter's share of the fleet."""

from __future__ import annotations

import re
from dataclasses import fields
from typing import Any

from overseer.config.errors import ConfigError
from overseer.config.parsers import parse_duration
from overseer.model import FleetLimits
from overseer.model.shard import Shard

KEYS = {f.name for f in fields(FleetLimits)}


def fleet_limits(raw: dict[str, Any]) -> FleetLimits:
    """The section from its mapping: durations, positive caps, and timeouts in their order."""
    values: dict[str, Any] = {}
    for f in fields(FleetLimits):
        if f.name not in raw:
            continue
        key = f"fleet.{f.name}"
        if f.name.startswith("max_"):
            value = raw[f.name]
            if not isinstance(value, int) or isinstance(value, bool) or value < 1:
                raise ConfigError(f"{key}: expected a positive integer, got {value!r}")
            values[f.name] = value
        else:
            values[f.name] = parse_duration(raw[f.name], key)
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


def parse_shard(value: object, key: str = "shard") -> Shard:
    """A `Shard` from `i/n` with 0 <= i < n."""
    match = re.fullmatch(r"(\d+)/(\d+)", value) if isinstance(value, str) else None
    if match is None or not 0 <= int(match.group(1)) < int(match.group(2)):
        raise ConfigError(f"{key}: expected i/n with 0 <= i < n, such as 0/2, got {value!r}")
    return Shard(int(match.group(1)), int(match.group(2)))
