"""The `events:` section: the event history's SQLite file, and how much of it to keep."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from overseer.config.options import Option, option
from overseer.config.parsers import boolean, parse_duration, parse_size, string

MIN_EVENTS_SIZE = 1_000_000


@dataclass(frozen=True)
class EventsConfig:
    """The event history: an SQLite file of the fleet's transitions, and how much of it to keep."""

    enabled: bool = True
    path: str = "overseer-events.db"  # relative to the working directory
    retention: float = 30 * 86400.0  # seconds
    max_size: int = 1_000_000_000  # bytes


OPTIONS: tuple[Option, ...] = (
    option("events.enabled", "true", "record the fleet's transitions (true or false)", metavar="BOOL"),
    option(
        "events.path",
        "overseer-events.db",
        "the event history's SQLite database, relative to the working directory; maintenance windows "
        "are kept there too",
        metavar="PATH",
    ),
    option("events.retention", "30d", "events older than this are deleted", metavar="DURATION"),
    option(
        "events.max_size",
        "1GB",
        "the oldest events are deleted when the database outgrows this (500MB, 1GB, 2GiB; at least 1MB)",
        metavar="SIZE",
    ),
)
KEYS = {entry.key.partition(".")[2] for entry in OPTIONS}


def events_config(raw: dict[str, Any]) -> EventsConfig:
    """The section from its mapping."""
    defaults = EventsConfig()
    return EventsConfig(
        enabled=boolean(raw.get("enabled", defaults.enabled), "events.enabled"),
        path=string(raw["path"], "events.path") if "path" in raw else defaults.path,
        retention=parse_duration(raw["retention"], "events.retention")
        if "retention" in raw
        else defaults.retention,
        max_size=(
            parse_max_size(raw["max_size"], "events.max_size") if "max_size" in raw else defaults.max_size
        ),
    )


def parse_max_size(value: object, key: str) -> int:
    """The database's size limit: bytes, or a size such as `500MB`, at least 1MB."""
    return parse_size(value, key, MIN_EVENTS_SIZE, "1MB")
