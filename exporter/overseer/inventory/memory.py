"""Writes the robots the fleet heard to the registry, every while and at stop, so a restart forgets none.

A save needs the whole fleet's answer: while an ingest worker restarts, the save waits for the next turn
rather than write a list that misses the worker's robots (the registry would forget them).
"""

from __future__ import annotations

import logging
import threading

from overseer.fleet.interface import Fleet, FleetPartUnavailable
from overseer.inventory.registry import RobotRegistry
from overseer.model import RememberedRobot

log = logging.getLogger(__name__)

SAVE_INTERVAL_SECONDS = 30.0


class RobotMemory:
    """The robots remembered: read from the registry at start, saved from the fleet while it runs."""

    def __init__(self, registry: RobotRegistry, interval: float = SAVE_INTERVAL_SECONDS) -> None:
        """Remember what `registry` holds; save to it every `interval` once started."""
        self._registry = registry
        self._interval = interval
        self._known = tuple(registry.load())
        self._fleet: Fleet | None = None
        self._stopping = threading.Event()
        self._thread: threading.Thread | None = None
        if self._known:
            log.info("remembered %d robots heard before this start", len(self._known))

    def remembered(self) -> tuple[RememberedRobot, ...]:
        """The robots heard, as last read or saved (what a fleet starting now follows)."""
        return self._known

    def start(self, fleet: Fleet) -> None:
        """Save what `fleet` heard every interval, from a thread of its own."""
        self._fleet = fleet
        self._thread = threading.Thread(target=self._save_loop, name="robot-memory", daemon=True)
        self._thread.start()

    def stop(self) -> None:
        """Save once more, with what each robot reported, then close the registry."""
        self._stopping.set()
        if self._thread is not None:
            self._thread.join(timeout=10)
        self.save(with_components=True)
        self._registry.close()

    def save(self, with_components: bool = False) -> bool:
        """Write what the fleet heard now; False when the fleet or the registry could not give or take it.

        `with_components` keeps each robot's components too (at a clean stop: a restarted exporter then
        shows them as they were, and its outputs carry on rather than start again).
        """
        if self._fleet is None:
            return False
        try:
            heard = tuple(self._fleet.heard(with_components))
        except FleetPartUnavailable as error:
            log.info("robots heard not saved this time: %s", error)
            return False
        if not self._registry.save(heard):
            return False
        self._known = heard
        return True

    def forget(self, robot: str) -> None:
        """Forget one robot at once (retired)."""
        self._known = tuple(known for known in self._known if known.name != robot)
        self._registry.forget(robot)

    def _save_loop(self) -> None:
        while not self._stopping.wait(self._interval):
            try:
                self.save()
            except Exception:  # a bug here must not end remembering for good
                log.exception("saving the robots heard failed")
