"""The `maintenance:` section: who may open and close windows, and the windows that recur."""

from __future__ import annotations

import datetime
import re
from dataclasses import dataclass
from typing import Any
from zoneinfo import ZoneInfo, ZoneInfoNotFoundError

from overseer.config.errors import ConfigError
from overseer.config.options import Option, file_only, option
from overseer.config.parsers import listed, reject_unknown, string
from overseer.model.maintenance import DAYS, RecurringWindow, RobotSelector

OPTIONS: tuple[Option, ...] = (
    option(
        "maintenance.writers",
        "none",
        "a basic-auth user (of the web config) who may open and end windows; repeat for several",
        kind="repeated",
        metavar="USER",
        flag="--maintenance.writer",
    ),
    file_only(
        "maintenance.windows",
        "none",
        "recurring windows: [{robots: night_shift/, from: '22:00', to: '06:00', days: [mon, tue], "
        "time_zone: Europe/Berlin, comment: parked}]",
        "a list of mappings",
    ),
)
KEYS = {entry.key.partition(".")[2] for entry in OPTIONS}
_WINDOW_KEYS = {"robots", "days", "from", "to", "time_zone", "comment"}
_TIME = re.compile(r"([01]\d|2[0-3]):([0-5]\d)")


@dataclass(frozen=True)
class MaintenanceConfig:
    """Users (of the web config's basic auth) allowed to write windows, and the recurring windows."""

    writers: tuple[str, ...] = ()
    windows: tuple[RecurringWindow, ...] = ()


def maintenance_config(raw: dict[str, Any]) -> MaintenanceConfig:
    """The section from its mapping."""
    writers = tuple(
        string(user, "maintenance.writers") for user in listed(raw.get("writers", []), "maintenance.writers")
    )
    windows = tuple(
        _recurring(item, index)
        for index, item in enumerate(listed(raw.get("windows", []), "maintenance.windows"))
    )
    return MaintenanceConfig(writers, windows)


def _recurring(item: object, index: int) -> RecurringWindow:
    key = f"maintenance.windows[{index}]"
    if not isinstance(item, dict):
        raise ConfigError(f"{key}: expected a mapping with robots, from, to, got {item!r}")
    reject_unknown(item, key + ".", _WINDOW_KEYS)
    try:
        robots = RobotSelector.parse(item.get("robots"))
    except ValueError as error:
        raise ConfigError(f"{key}.robots: {error}") from None
    days = item.get("days", list(DAYS))
    if not isinstance(days, list) or not days or any(day not in DAYS for day in days):
        raise ConfigError(f"{key}.days: expected a list of {', '.join(DAYS)}, got {days!r}")
    begins, ends = _time(item.get("from"), f"{key}.from"), _time(item.get("to"), f"{key}.to")
    if begins == ends:
        raise ConfigError(f"{key}.to: must differ from {key}.from, got {item.get('to')!r}")
    zone_name = string(item.get("time_zone", "UTC"), f"{key}.time_zone")
    try:
        zone = ZoneInfo(zone_name)
    except (ZoneInfoNotFoundError, ValueError):
        raise ConfigError(
            f"{key}.time_zone: expected a time zone such as Europe/Berlin, got {zone_name!r}"
        ) from None
    comment = string(item.get("comment", "recurring maintenance"), f"{key}.comment")
    return RecurringWindow(
        index, robots, frozenset(DAYS.index(day) for day in days), begins, ends, zone, comment
    )


def _time(value: object, key: str) -> datetime.time:
    match = _TIME.fullmatch(value) if isinstance(value, str) else None
    if match is None:
        raise ConfigError(f"{key}: expected a time of day HH:MM such as 22:00, got {value!r}")
    return datetime.time(int(match.group(1)), int(match.group(2)))
