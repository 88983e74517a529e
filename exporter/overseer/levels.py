"""ROS diagnostic levels, their Nagios meaning, and the severity order used to pick the worst."""

from __future__ import annotations

from collections.abc import Iterable
from enum import IntEnum


class Level(IntEnum):
    """A diagnostic level; the numbers are ROS's and Nagios's (OK, WARNING, CRITICAL, UNKNOWN)."""

    OK = 0
    WARN = 1
    ERROR = 2
    STALE = 3


# ERROR > WARN > STALE > OK, as Nagios ranks CRITICAL > WARNING > UNKNOWN > OK; a numeric max is wrong.
_SEVERITY_RANK = {Level.OK: 0, Level.STALE: 1, Level.WARN: 2, Level.ERROR: 3}


def severity_rank(level: Level) -> int:
    """Rank of a level in the severity order (higher is worse)."""
    return _SEVERITY_RANK[level]


def worst(levels: Iterable[Level]) -> Level:
    """The most severe level in `levels` by the severity order; OK when empty."""
    result = Level.OK
    rank = 0
    for level in levels:
        level_rank = _SEVERITY_RANK[level]
        if level_rank > rank:
            result, rank = level, level_rank
            if rank == 3:
                break
    return result
