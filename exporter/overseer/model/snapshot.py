"""An immutable view of the fleet at one instant, and the judgements that depend on time.

Staleness and robot up/down are derived from the snapshot's time, never stored, so they cannot drift
from the clock. This is the one place that judges them: every output (metrics, API, event history,
Icinga 2) asks the snapshot, and so says the same thing at the same instant.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field

from overseer.levels import Level, worst
from overseer.model.state import Component, ComponentKey, FleetLimits, RobotState


@dataclass(frozen=True)
class FleetSnapshot:
    """An immutable view of the fleet at `taken_at`, with the judgements that depend on time."""

    taken_at: float
    limits: FleetLimits
    robots: tuple[RobotState, ...]
    message_counts: Mapping[tuple[str, str], int] = field(default_factory=dict)
    dropped_statuses: Mapping[str, int] = field(default_factory=dict)
    truncated_strings: int = 0
    source_errors: Mapping[tuple[str, str], int] = field(default_factory=dict)

    def robot_up(self, robot: RobotState) -> bool:
        """True while the robot's messages arrive within `robot_timeout` and its publisher is alive."""
        return (
            robot.publisher_alive
            and robot.last_message is not None
            and self.taken_at - robot.last_message <= self.limits.robot_timeout
        )

    def went_down_at(self, robot: RobotState) -> float:
        """When a robot that is down went down: `robot_timeout` after its last message (or discovery).

        When its publisher left first, the transport said so at once: then it went down now.
        """
        last = robot.last_message if robot.last_message is not None else robot.discovered_at
        timed_out = last + self.limits.robot_timeout
        return min(self.taken_at, timed_out) if not robot.publisher_alive else timed_out

    @property
    def stale_before(self) -> float:
        """Updates before this unix time are stale now (`stale_after` ago)."""
        return self.taken_at - self.limits.stale_after

    def went_stale_at(self, updated: float) -> float:
        """When something last updated at `updated` turned (or turns) STALE."""
        return updated + self.limits.stale_after

    @staticmethod
    def last_update(robot: RobotState, key: ComponentKey, component: Component) -> float:
        """When the component was last reported."""
        if robot.last_message is not None and key not in robot.missing:
            return robot.last_message
        return component.last_update

    def component_level(
        self, robot: RobotState, key: ComponentKey, component: Component, robot_up: bool
    ) -> Level:
        """The component's level now: STALE when not updated for `stale_after` or its robot is down."""
        if not robot_up or not self.fresh(self.last_update(robot, key, component)):
            return Level.STALE
        return component.level

    def fresh(self, updated: float | None) -> bool:
        """True when something updated at `updated` (None: never) is within `stale_after` of now."""
        return updated is not None and updated >= self.stale_before

    def component_levels(self, robot: RobotState, robot_up: bool) -> list[Level]:
        """Every component's level now, in the order of `robot.components` (as `component_level`)."""
        if not robot_up:
            return [Level.STALE] * len(robot.components)
        fresh = self.fresh(robot.last_message)
        missing = robot.missing
        if not missing:  # almost always: every level follows from the latest message's time
            if fresh:
                return [component.level for component in robot.components.values()]
            return [Level.STALE] * len(robot.components)
        return [
            self.component_level(robot, key, component, True)
            if key in missing
            else (component.level if fresh else Level.STALE)
            for key, component in robot.components.items()
        ]

    def robot_level(self, robot: RobotState) -> Level:
        """The robot's worst component level by severity order (STALE when the robot is down)."""
        if not self.robot_up(robot):
            return Level.STALE
        return worst(self.component_levels(robot, True))

    def find(self, name: str) -> RobotState | None:
        """The robot called `name`, or None."""
        for robot in self.robots:
            if robot.name == name:
                return robot
        return None
