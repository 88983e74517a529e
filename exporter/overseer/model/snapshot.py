"""An immutable view of the fleet at one instant, and the judgements that depend on time.

Staleness and robot up/down are derived from the snapshot's time, never stored, so they cannot drift
from the clock. This is the one place that judges them: every output (metrics, API, event history,
Icinga 2) asks the snapshot, and so says the same thing at the same instant. Ages are judged on the
monotonic clock (`taken_at`); `generated_at` is the wall clock at the same instant, for reports.

A component is STALE when it has not been updated for longer than its feed allows (`stale_after`, or
`stale_periods` of the feed's learned period when that is longer), or than its name's override says; a
robot is down when silent for longer than `robot_timeout` (or `stale_periods` of its own period), or from
its last publisher's departure until it speaks again.
"""

from __future__ import annotations

import bisect
from collections.abc import Mapping
from dataclasses import dataclass, field
from functools import lru_cache
from typing import NamedTuple

from overseer.levels import Level, worst
from overseer.model.inventory import EXPECTED_FEED
from overseer.model.state import (
    Component,
    ComponentKey,
    FleetLimits,
    Forgetting,
    RobotState,
    StaleOverride,
    feed_stale_after,
    robot_timeout,
)

_STALE = Level.STALE


class RobotTiming(NamedTuple):
    """When a robot's components turn STALE, as far as it follows from one revision of the robot.

    `feed_bounds` holds, for each feed (by index), the sorted distinct ages at which the components it
    carries turn STALE; `own_deadlines` the sorted monotonic times at which the components missing from
    their feed's latest message do. `staleness` counts what has passed of both: while that count holds,
    every component's level holds.
    """

    feed_bounds: tuple[tuple[float, ...], ...]
    own_deadlines: tuple[float, ...]


@dataclass(frozen=True)
class FleetSnapshot:
    """An immutable view of the fleet at `taken_at` (monotonic), with the judgements that depend on time."""

    taken_at: float
    limits: FleetLimits
    robots: tuple[RobotState, ...]
    message_counts: Mapping[tuple[str, str], int] = field(default_factory=dict)
    dropped_statuses: Mapping[str, int] = field(default_factory=dict)
    truncated_strings: int = 0
    source_errors: Mapping[tuple[str, str], int] = field(default_factory=dict)
    generated_at: float = 0.0  # the wall clock when it was taken (unix time)
    forgotten: Mapping[str, Forgetting] = field(default_factory=dict)  # the last robots forgotten, and why
    forgotten_counts: Mapping[str, int] = field(default_factory=dict)  # robots forgotten, by reason

    def robot_up(self, robot: RobotState) -> bool:
        """True while the robot's messages arrive within its timeout, and since its publisher's departure."""
        last = robot.last_message
        if last is None or (robot.left_at is not None and last <= robot.left_at):
            return False
        silent = self.taken_at - last
        # Within the shortest timeout any robot has, the robot's own (longer for a slow one) need not be
        # worked out: almost every robot, at every look.
        return silent <= self.limits.robot_timeout or silent <= robot_timeout(self.limits, robot)

    def went_down_at(self, robot: RobotState) -> float:
        """When a robot that is down went down (monotonic).

        That is its timeout after its last message (or its discovery), or its publisher's departure when
        that came first.
        """
        timed_out = robot.last_seen + robot_timeout(self.limits, robot)
        if not robot.publisher_alive and robot.left_at is not None:
            return min(robot.left_at, timed_out)
        return timed_out

    def robot_timeout(self, robot: RobotState) -> float:
        """How long `robot` may be silent before it is down."""
        return robot_timeout(self.limits, robot)

    @staticmethod
    def last_update(robot: RobotState, key: ComponentKey, component: Component) -> float:
        """When the component was last reported (monotonic)."""
        if key not in robot.missing:
            for feed in robot.feeds:
                if feed.name == component.feed:
                    return feed.last_message
        return component.last_update

    def stale_after(self, robot: RobotState, component: Component) -> float:
        """How long `component` stays fresh without an update: its name's override, or its feed's bound."""
        overrides = self.limits.stale_overrides
        if overrides:
            override = _override(overrides, component.key[0])
            if override is not None:
                return override
        return feed_stale_after(self.limits, robot.feed(component.feed))

    def went_stale_at(self, robot: RobotState, key: ComponentKey, component: Component) -> float:
        """When the component turned (or turns) STALE, robot up (monotonic)."""
        return self.last_update(robot, key, component) + self.stale_after(robot, component)

    def fresh(self, robot: RobotState, key: ComponentKey, component: Component) -> bool:
        """True while the component has been updated within its bound."""
        return self.taken_at - self.last_update(robot, key, component) <= self.stale_after(robot, component)

    def component_level(
        self, robot: RobotState, key: ComponentKey, component: Component, robot_up: bool
    ) -> Level:
        """The component's level now: STALE when not updated within its bound or its robot is down."""
        if not robot_up or not self.fresh(robot, key, component):
            return _STALE
        return component.level

    def component_levels(self, robot: RobotState, robot_up: bool) -> list[Level]:
        """Every component's level now, in the order of `robot.components` (as `component_level`)."""
        components = robot.components
        if not robot_up:
            return [_STALE] * len(components)
        feeds = robot.feeds
        limits = self.limits
        if len(feeds) == 1 and not robot.missing and not limits.stale_overrides:
            # Almost always: one feed carries every component, so they share one time and one bound.
            feed = feeds[0]
            if self.taken_at - feed.last_message <= feed_stale_after(limits, feed):
                return [component.level for component in components.values()]
            return [_STALE] * len(components)
        fresh = self.fresh
        return [c.level if fresh(robot, key, c) else _STALE for key, c in components.items()]

    def robot_level(self, robot: RobotState) -> Level:
        """The robot's worst component level by severity order (STALE when the robot is down)."""
        if not self.robot_up(robot):
            return _STALE
        return worst(self.component_levels(robot, True))

    def timing(self, robot: RobotState) -> RobotTiming:
        """When the robot's components turn STALE, for `staleness`.

        It is the same for every snapshot of one revision of the robot, so a caller may keep it.
        """
        feeds = robot.feeds
        if len(feeds) == 1 and not robot.missing and not self.limits.stale_overrides:
            return RobotTiming(((feed_stale_after(self.limits, feeds[0]),),), ())
        bounds: list[set[float]] = [set() for _ in robot.feeds]
        index = {feed.name: position for position, feed in enumerate(robot.feeds)}
        own: list[float] = []
        missing = robot.missing
        for key, component in robot.components.items():
            if component.feed == EXPECTED_FEED:
                continue  # a stand-in is STALE whatever the time
            if key in missing or component.feed not in index:
                own.append(component.last_update + self.stale_after(robot, component))
            else:
                bounds[index[component.feed]].add(self.stale_after(robot, component))
        return RobotTiming(tuple(tuple(sorted(b)) for b in bounds), tuple(sorted(own)))

    def staleness(self, robot: RobotState, timing: RobotTiming) -> tuple[int, ...]:
        """How far the robot's components have gone STALE, by `timing`: equal counts, equal levels."""
        taken_at = self.taken_at
        counts = [
            bisect.bisect_left(bounds, taken_at - feed.last_message)
            for feed, bounds in zip(robot.feeds, timing.feed_bounds, strict=True)
        ]
        counts.append(bisect.bisect_left(timing.own_deadlines, taken_at))
        return tuple(counts)

    def find(self, name: str) -> RobotState | None:
        """The robot called `name`, or None."""
        for robot in self.robots:
            if robot.name == name:
                return robot
        return None


@lru_cache(maxsize=65_536)
def _override(overrides: tuple[StaleOverride, ...], name: str) -> float | None:
    """The stale bound the first override matching `name` sets, or None (names repeat across a fleet)."""
    for override in overrides:
        if override.pattern.fullmatch(name):
            return override.stale_after
    return None
