"""ROS diagnostic levels, their Nagios meaning, and the severity order used to pick the worst."""

from __future__ import annotations

from collections.abc import Iterable
from enum import IntEnum

from overseer.severity import SEVERITY_RANK, WORST_RANK


class Level(IntEnum):
    """A diagnostic level; the numbers are ROS's and Nagios's (OK, WARNING, CRITICAL, UNKNOWN)."""

    OK = 0
    WARN = 1
    ERROR = 2
    STALE = 3


def severity_rank(level: Level) -> int:
    """Rank of a level in the severity order (higher is worse; `overseer.severity`)."""
    return SEVERITY_RANK[level]


def worst(levels: Iterable[Level]) -> Level:
    """The most severe level in `levels` by the severity order; OK when empty."""
    result = Level.OK
    rank = 0
    for level in levels:
        level_rank = SEVERITY_RANK[level]
        if level_rank > rank:
            result, rank = level, level_rank
            if rank == WORST_RANK:
                break
    return result
