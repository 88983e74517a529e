"""What changes of a robot must reach its readers at once (up or down, a component's level), kept cheap.

Each robot's signature is worked out again only when its revision, up or staleness changed, and handed
out as a digest: a number that changes with the signature. A reader holding the fleet in other processes
(the Icinga 2 push over ingest workers) compares digests and fetches only the robots whose digest moved,
instead of the whole fleet every look.
"""

from __future__ import annotations

import bisect
import math
from typing import NamedTuple

from overseer.model import FleetSnapshot, RobotState
from overseer.model.snapshot import RobotTiming


def robot_signature(snapshot: FleetSnapshot, robot: RobotState) -> tuple[object, ...]:
    """What a change of must be pushed at once: up or down, and every component's level now."""
    up = snapshot.robot_up(robot)
    return (up, tuple(robot.components), tuple(snapshot.component_levels(robot, up)))


def awaiting(snapshot: FleetSnapshot, robot: RobotState) -> bool:
    """True for a robot heard before this start, up then, not heard since: nothing new to push yet.

    Until it speaks again (or its timeout passes and it is down) Icinga's last results stand; pushing a
    robot whose components a crash left unknown would turn its services UNKNOWN for a few seconds.
    """
    return robot.last_message is not None and not robot.feeds and snapshot.robot_up(robot)


def holds_until(snapshot: FleetSnapshot, robot: RobotState, timing: RobotTiming) -> float:
    """The last time (monotonic) at which this version of `robot` is as up and as stale as at the snapshot."""
    taken_at = snapshot.taken_at
    until = math.inf
    if robot.last_message is not None and snapshot.robot_up(robot):  # down, it stays down: no bound
        until = robot.last_message + snapshot.robot_timeout(robot)
    for feed, bounds in zip(robot.feeds, timing.feed_bounds, strict=True):
        passed = bisect.bisect_left(bounds, taken_at - feed.last_message)
        if passed < len(bounds):
            until = min(until, feed.last_message + bounds[passed])
    passed = bisect.bisect_left(timing.own_deadlines, taken_at)
    if passed < len(timing.own_deadlines):
        until = min(until, timing.own_deadlines[passed])
    return until


# A robot's revision, discovery, last message, publisher's departure and its feeds' last messages.
_Version = tuple[int, float, float | None, float | None, float | tuple[float, ...]]


class _Known(NamedTuple):
    """What `Signatures` keeps of one robot."""

    version: _Version  # of the robot looked at last
    until: float  # until when (monotonic) that version's up and staleness hold
    key: tuple[object, ...]  # its revision, up and staleness
    timing: RobotTiming
    digest: int  # its signature's


class Signatures:
    """Each robot's `robot_signature` digest, worked out again only when a revision, up or staleness changed.

    At 10,000 robots, working every one out at every look of the push took a third of a core: a robot
    republishing the same array keeps its revision, its staleness holds between messages, and a robot
    not heard since the last look is the same version, whose levels hold until a component's bound or the
    robot's timeout passes.
    """

    def __init__(self) -> None:
        """Nothing known yet."""
        self._known: dict[str, _Known] = {}

    def digests(self, snapshot: FleetSnapshot) -> dict[str, int | None]:
        """Every robot of `snapshot` → its signature's digest, None while it is `awaiting`.

        Robots no longer in the snapshot are forgotten. A digest is the signature's hash: equal
        signatures give equal digests within one process (not across processes, whose string hashes
        differ: a restarted ingest worker's robots look changed once), and different ones differ but for
        a chance in 2**64.
        """
        known = self._known
        self._known = {}
        digests: dict[str, int | None] = {}
        for robot in snapshot.robots:
            if robot.name in known:
                self._known[robot.name] = known[robot.name]
            digests[robot.name] = None if awaiting(snapshot, robot) else self._look(snapshot, robot).digest
        return digests

    def _look(self, snapshot: FleetSnapshot, robot: RobotState) -> _Known:
        known = self._known.get(robot.name)
        version = _version(robot)
        if known is not None and known.version == version and snapshot.taken_at <= known.until:
            return known
        # A robot forgotten and followed again starts its revisions over: its discovery tells them apart.
        revision = (robot.revision, robot.discovered_at)
        timing = known.timing if known is not None and known.key[0] == revision else snapshot.timing(robot)
        key = (revision, snapshot.robot_up(robot), snapshot.staleness(robot, timing))
        until = holds_until(snapshot, robot, timing)
        if known is not None and known.key == key:
            kept = known._replace(version=version, until=until)
        else:
            kept = _Known(version, until, key, timing, hash(robot_signature(snapshot, robot)))
        self._known[robot.name] = kept
        return kept


def _version(robot: RobotState) -> _Version:
    """What tells one version of `robot` from another for its digest: all it depends on but the records.

    Not the version itself: kept until the next look, each robot's last one held every component it
    replaced alive beside the model's (84 B a component, when a fifth of them changed, at every look).
    A robot's revision changes with anything its judgement depends on but its feeds' times: those are
    its last message and each feed's (a feed touched at the very moment of another's message moves its
    own time alone).
    """
    feeds = robot.feeds
    times = feeds[0].last_message if len(feeds) == 1 else tuple([feed.last_message for feed in feeds])
    return robot.revision, robot.discovered_at, robot.last_message, robot.left_at, times
