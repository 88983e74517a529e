"""When a robot's results are due again: each robot at its own phase of the interval.

Robots first queued together (a fleet first heard, every robot in one look) would otherwise be due
together at every interval after it: the whole fleet's results built, held and sent in one burst an
interval, where spread over it they cost the same a second all the time.
"""

from __future__ import annotations

import zlib

LEAST_SHARE = 0.25  # a robot sent now (its level changed) is not sent again within this share of an interval


def phase(robot: str, interval: float) -> float:
    """Where in every interval `robot`'s results repeat, from its name: the same in every run."""
    return zlib.crc32(robot.encode()) / 2**32 * interval


def next_due(robot: str, now: float, interval: float) -> float:
    """The first of `robot`'s phase points a quarter of an interval or more after `now`.

    A robot sent at its phase point is next due an interval later; one sent between (a change) at most
    1.25 intervals later, within the two intervals Icinga trusts a result (`Icinga2Config.ttl`).
    """
    earliest = now + LEAST_SHARE * interval
    return earliest + (phase(robot, interval) - earliest) % interval
