"""Feeds moved to another robot, forgotten by the robot that first had them one discovery round later.

A publisher of the absolute `/diagnostics` whose node the ROS graph has not told within a grace is taken
for its domain's robot; when the graph names its node later (Fast DDS sends a late reader a node's graph
at its next heartbeat, 3 s on), the source moves it to its node's robot. A message taken just before the
move may still be on its way to the old robot, so the old robot forgets the feed a round later, not at once.
"""

from __future__ import annotations

from collections.abc import Callable

from overseer.model import FleetModel


class MovedFeeds:
    """Feeds that left a robot for another, waiting for the next discovery round to be forgotten."""

    def __init__(self, model: FleetModel) -> None:
        """Forget the moved feeds in `model`."""
        self._model = model
        self._moved: list[tuple[str, str]] = []

    def moved(self, robot: str, feed: str) -> None:
        """`feed` no longer belongs to `robot`: forget it at the next `forget`."""
        self._moved.append((robot, feed))

    def forget(self, followed: Callable[[str], bool]) -> None:
        """Forget the feeds moved before now; a robot `followed` through no other goes with its last."""
        moved, self._moved = self._moved, []
        for robot, feed in moved:
            self._model.forget_feed(robot, feed, last=not followed(robot))
