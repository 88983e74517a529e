"""Feeds moved to another robot, forgotten by the robot that first had them a second later.

A publisher of the absolute `/diagnostics` whose node the ROS graph has not told within a grace is taken
for its domain's robot; when the graph names its node later (Fast DDS sends a late reader a node's graph
at its next heartbeat, 3 s on), the source moves it to its node's robot. A message taken just before the
move may still be on its way to the old robot, so the old robot forgets the feed a second later, not at
once.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from typing import Protocol

FORGET_AFTER_SECONDS = 1.0  # a message taken before the move has long been applied by then


class FeedForgetting(Protocol):
    """Where a moved feed is forgotten: the fleet model, or what hands a source's robots on to it."""

    def forget_feed(self, robot: str, feed: str, last: bool) -> None:
        """Drop what `feed` told of `robot`; `last`: the source hears `robot` through no other publisher."""


class MovedFeeds:
    """Feeds that left a robot for another, waiting to be forgotten by the robot they left."""

    def __init__(self, model: FeedForgetting, clock: Callable[[], float] = time.monotonic) -> None:
        """Forget the moved feeds in `model`, timed by `clock`."""
        self._model = model
        self._clock = clock
        self._lock = threading.Lock()  # a source may move feeds in one thread and forget in another
        self._moved: list[tuple[float, str, str]] = []  # (when, robot, feed)

    def moved(self, robot: str, feed: str) -> None:
        """`feed` no longer belongs to `robot`: forget it at a `forget` a second from now."""
        with self._lock:
            self._moved.append((self._clock(), robot, feed))

    def forget(self, followed: Callable[[str], bool]) -> None:
        """Forget the feeds moved a second ago or more; `followed` tells a robot the source still hears."""
        if not self._moved:
            return
        horizon = self._clock() - FORGET_AFTER_SECONDS
        with self._lock:
            due = [moved for moved in self._moved if moved[0] <= horizon]
            self._moved = [moved for moved in self._moved if moved[0] > horizon]
        for _, robot, feed in due:
            self._model.forget_feed(robot, feed, last=not followed(robot))
