"""Retiring a robot: forgotten on purpose, at once, everywhere, with who did it in the event history."""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass

from overseer.fleet.interface import Fleet
from overseer.inventory.memory import RobotMemory
from overseer.model.events import Event, EventSink

# The outcomes of a request to retire, and the HTTP status each answers with.
RETIRED, UNKNOWN, LISTED, UP = "retired", "unknown", "listed", "up"


@dataclass(frozen=True)
class Retirement:
    """What a request to retire a robot came to: its outcome and what to tell the asker."""

    outcome: str
    text: str


class Retirements:
    """Forgets robots that are down and not listed: from the fleet, the memory, with an event."""

    def __init__(
        self,
        fleet: Fleet,
        memory: RobotMemory,
        events: EventSink | None,
        clock: Callable[[], float] = time.time,
    ) -> None:
        """Retire robots of `fleet`, forgetting them in `memory`; `events` records each retirement."""
        self._fleet = fleet
        self._memory = memory
        self._events = events
        self._clock = clock

    def retire(self, robot: str, author: str, comment: str) -> Retirement:
        """Retire `robot` for `author`, saying `comment`; `FleetPartUnavailable` while its worker restarts."""
        outcome = self._fleet.retire(robot)
        if outcome == UNKNOWN:
            return Retirement(outcome, f"no robot {robot!r} is followed")
        if outcome == LISTED:
            return Retirement(
                outcome, f"robot {robot!r} is in the inventory: remove it there (and reload) to forget it"
            )
        if outcome == UP:
            return Retirement(outcome, f"robot {robot!r} is up: only a robot that is down can be retired")
        self._memory.forget(robot)
        message = f"retired by {author}" + (f": {comment}" if comment else "")
        if self._events is not None:
            self._events([Event(self._clock(), robot, "retired", message=message)])
        return Retirement(RETIRED, message)
