"""When a robot's results are due again: each robot at its own moment of the interval.

Robots first queued together (a fleet first heard, every robot in one look) would otherwise be due
together at every interval after it: the whole fleet's results built, held and sent in one burst an
interval, where spread over it they cost the same a second all the time.
"""

from __future__ import annotations

import zlib


def phase(robot: str, interval: float) -> float:
    """Where in every interval `robot`'s results repeat, from its name alone (kept over restarts)."""
    return zlib.crc32(robot.encode()) / 2**32 * interval


def next_due(robot: str, now: float, interval: float) -> float:
    """The first of `robot`'s moments after `now`: an interval later for a robot sent at its moment.

    A robot sent between two of its moments (its level changed) is due at the next one, so at most an
    interval passes between two of its results, as the TTL of two intervals expects (`Icinga2Config.ttl`).
    """
    wait = (phase(robot, interval) - now) % interval
    return now + (wait if wait > 0 else interval)
