"""A window asked for in a request's JSON body, read strictly: every error names the field."""

from __future__ import annotations

import datetime
import math
from dataclasses import dataclass
from typing import Any

from overseer.config import ConfigError
from overseer.config.parsers import parse_duration
from overseer.maintenance.schedule import WindowError
from overseer.model.maintenance import RobotSelector

FIELDS = ("robots", "start", "end", "duration", "comment")


@dataclass(frozen=True)
class WindowRequest:
    """What POST /api/v1/maintenance asks for; `end` is resolved from `duration` when given so."""

    robots: RobotSelector
    start: float | None
    end: float
    comment: str


def parse_window_request(document: object, now: float) -> WindowRequest:
    """The window `document` (a decoded JSON body) asks for; `WindowError` naming the field otherwise."""
    if not isinstance(document, dict):
        raise WindowError("body: expected a JSON object with robots, comment, and end or duration")
    unknown = sorted(str(key) for key in document if key not in FIELDS)
    if unknown:
        raise WindowError(f"{unknown[0][:64]!r}: unknown field (expected {', '.join(FIELDS)})")
    try:
        robots = RobotSelector.parse(document.get("robots"))
    except ValueError as error:
        raise WindowError(f"robots: {error}") from None
    start = None if document.get("start") is None else parse_time(document["start"], "start")
    if (document.get("end") is None) == (document.get("duration") is None):
        raise WindowError("end: give either end or duration")
    if document.get("end") is not None:
        end = parse_time(document["end"], "end")
    else:
        try:
            end = (now if start is None else start) + parse_duration(document["duration"], "duration")
        except ConfigError as error:
            raise WindowError(str(error)) from None
    comment = document.get("comment")
    if not isinstance(comment, str):
        raise WindowError(f"comment: expected a string saying why, got {_shown(comment)}")
    return WindowRequest(robots, start, end, comment)


def parse_time(value: object, field: str) -> float:
    """Unix seconds from a number or an RFC 3339 time with its offset (`2026-11-24T06:00:00+01:00`)."""
    if isinstance(value, int | float) and not isinstance(value, bool) and math.isfinite(value):
        return float(value)
    if isinstance(value, str) and len(value) <= 64:
        try:
            parsed = datetime.datetime.fromisoformat(value.replace("Z", "+00:00"))
        except ValueError:
            parsed = None
        if parsed is not None and parsed.tzinfo is not None:
            return parsed.timestamp()
    raise WindowError(
        f"{field}: expected unix seconds or an RFC 3339 time with its offset, such as 2026-11-24T06:00:00Z, "
        f"got {_shown(value)}"
    )


def _shown(value: Any) -> str:
    text = repr(value)
    return text if len(text) <= 80 else text[:77] + "..."
