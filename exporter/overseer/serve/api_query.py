"""The parameters of GET /api/v1/components and /api/v1/robots read into queries; a bad one is a clear 400."""

from __future__ import annotations

from collections.abc import Mapping, Sequence

from overseer.fleet.documents import (
    COMPONENTS_DEFAULT_LIMIT,
    COMPONENTS_MAX_LIMIT,
    ComponentQuery,
    RobotQuery,
)
from overseer.levels import Level

QUERY_MAX_LENGTH = 256
_LEVEL_NAMES = ", ".join(level.name for level in Level)


class ApiQueryError(ValueError):
    """A query parameter the API cannot honour; the message names the parameter and its value."""


MAX_LABELS_ASKED = 32


def parse_robot_query(params: Mapping[str, Sequence[str]]) -> RobotQuery | None:
    """The query of GET /api/v1/robots: `label=NAME=VALUE`, repeatable (every one must hold); None: all."""
    labels = []
    for value in params.get("label", ()):
        name, equals, wanted = value.partition("=")
        if not equals or not name or len(value) > QUERY_MAX_LENGTH:
            raise ApiQueryError(f"label: expected NAME=VALUE, got {value[:QUERY_MAX_LENGTH]!r}")
        labels.append((name, wanted))
    if len(labels) > MAX_LABELS_ASKED:
        raise ApiQueryError(f"label: at most {MAX_LABELS_ASKED}, got {len(labels)}")
    return RobotQuery(tuple(labels)) if labels else None


def parse_component_query(params: Mapping[str, Sequence[str]]) -> ComponentQuery:
    """The query of GET /api/v1/components from its parameters (as `urllib.parse.parse_qs` gives them)."""
    levels: set[Level] | None = None
    for value in params.get("level", ()):
        for word in value.split(","):
            word = word.strip()
            if not word:
                continue
            level = _level_named(word)
            if level is None:
                raise ApiQueryError(f"level: expected {_LEVEL_NAMES} or 0-3, got {word!r}")
            levels = (levels or set()) | {level}
    text = _last(params, "q") or ""
    if len(text) > QUERY_MAX_LENGTH:
        raise ApiQueryError(f"q: longer than {QUERY_MAX_LENGTH} characters ({len(text)})")
    limit_text = _last(params, "limit")
    limit = COMPONENTS_DEFAULT_LIMIT
    if limit_text is not None:
        if not limit_text.isdigit() or not 1 <= int(limit_text) <= COMPONENTS_MAX_LIMIT:
            raise ApiQueryError(
                f"limit: expected a whole number from 1 to {COMPONENTS_MAX_LIMIT}, got {limit_text!r}"
            )
        limit = int(limit_text)
    return ComponentQuery(
        None if levels is None else frozenset(levels), text, _last(params, "robot") or None, limit
    )


def _level_named(word: str) -> Level | None:
    if word.isdigit():
        return Level(int(word)) if int(word) in Level._value2member_map_ else None
    return Level.__members__.get(word.upper())


def _last(params: Mapping[str, Sequence[str]], name: str) -> str | None:
    values = params.get(name)
    return values[-1] if values else None
