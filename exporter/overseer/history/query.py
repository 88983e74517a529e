"""The filters of GET /api/v1/events, read from a query string; every error names its parameter."""

from __future__ import annotations

import base64
import binascii
import datetime
import math
import re
from dataclasses import dataclass
from urllib.parse import parse_qs

from overseer.levels import Level

DEFAULT_LIMIT = 100
MAX_LIMIT = 1000
PARAMETERS = ("robot", "component", "level", "since", "until", "limit", "before")
_CURSOR = re.compile(r"(-?\d+(?:\.\d+)?(?:e[-+]?\d+)?)/(\d+)")


class QueryError(ValueError):
    """A query parameter that cannot be used; the message names it."""


@dataclass(frozen=True)
class EventQuery:
    """Which events to return, newest first: every filter given must match."""

    robot: str | None = None  # exact robot name
    component: str | None = None  # substring of the component name, case-sensitive
    levels: tuple[Level, ...] = ()  # new_state is one of these
    since: float | None = None  # time >= since
    until: float | None = None  # time <= until
    limit: int = DEFAULT_LIMIT
    before: tuple[float, int] | None = None  # (time, id) of the last event of the previous page


def encode_cursor(time: float, event_id: int) -> str:
    """The opaque `next` cursor pointing after the event (`time`, `event_id`)."""
    return base64.urlsafe_b64encode(f"{time!r}/{event_id}".encode()).decode().rstrip("=")


def decode_cursor(cursor: str) -> tuple[float, int]:
    """(time, id) from a cursor made by `encode_cursor`."""
    try:
        text = base64.urlsafe_b64decode(cursor + "=" * (-len(cursor) % 4)).decode("ascii")
    except (binascii.Error, UnicodeDecodeError, ValueError):
        text = ""
    match = _CURSOR.fullmatch(text)
    if match is None or not math.isfinite(float(match.group(1))):
        raise QueryError(f"before: expected a cursor from a previous answer's 'next', got {cursor!r}")
    return float(match.group(1)), int(match.group(2))


def parse_event_query(query_string: str) -> EventQuery:
    """An `EventQuery` from the query string of a request (without the `?`)."""
    try:
        raw = parse_qs(query_string, keep_blank_values=True, strict_parsing=False, max_num_fields=64)
    except ValueError as error:
        raise QueryError(f"query: cannot be read: {error}") from None
    for name, values in raw.items():
        if name not in PARAMETERS:
            shown = name if name.isprintable() else repr(name)
            raise QueryError(f"{shown}: unknown parameter (expected one of {', '.join(PARAMETERS)})")
        if len(values) > 1:
            raise QueryError(f"{name}: given {len(values)} times; give it once")
    given = {name: values[0] for name, values in raw.items()}
    for name in ("robot", "component"):
        if name in given and not given[name]:
            raise QueryError(f"{name}: must not be empty")
    query = EventQuery(
        robot=given.get("robot"),
        component=given.get("component"),
        levels=_levels(given["level"]) if "level" in given else (),
        since=_time(given["since"], "since") if "since" in given else None,
        until=_time(given["until"], "until") if "until" in given else None,
        limit=_limit(given["limit"]) if "limit" in given else DEFAULT_LIMIT,
        before=decode_cursor(given["before"]) if "before" in given else None,
    )
    if query.since is not None and query.until is not None and query.until < query.since:
        raise QueryError(f"until: must not be before since, got {given['until']!r}")
    return query


def _levels(text: str) -> tuple[Level, ...]:
    levels = []
    for name in text.split(","):
        level = Level.__members__.get(name.strip().upper())
        if level is None:
            raise QueryError(f"level: expected state names among OK, WARN, ERROR, STALE, got {text!r}")
        levels.append(level)
    return tuple(dict.fromkeys(levels))


def _time(text: str, name: str) -> float:
    """Unix seconds, or an RFC 3339 time with its offset (`2026-11-23T08:00:00Z`)."""
    try:
        seconds = float(text)
    except ValueError:
        try:
            stripped = text.strip()
            if stripped[-1:] in ("Z", "z"):  # Python 3.10's fromisoformat does not know Z
                stripped = stripped[:-1] + "+00:00"
            moment = datetime.datetime.fromisoformat(stripped)
        except ValueError:
            moment = None
        if moment is None or moment.tzinfo is None or "T" not in text.upper():
            raise QueryError(
                f"{name}: expected Unix seconds or an RFC 3339 time such as 2026-11-23T08:00:00Z, "
                f"got {text!r}"
            ) from None
        seconds = moment.timestamp()
    if not math.isfinite(seconds):
        raise QueryError(f"{name}: expected a finite time, got {text!r}")
    return seconds


def _limit(text: str) -> int:
    if not re.fullmatch(r"[0-9]{1,9}", text) or not 1 <= int(text) <= MAX_LIMIT:
        raise QueryError(f"limit: expected an integer from 1 to {MAX_LIMIT}, got {text!r}")
    return int(text)
