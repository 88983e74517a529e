"""Turns the fleet's changes into events: a hook for what robots report, a diff for what time decides.

Reported level changes come from the model's level listener, called as each message is applied: every
change is seen with its exact message and time, even one that flips back within a second, and it costs
nothing while levels hold. STALE, robot down and up, missing and expired follow from time or from
messages that changed nothing a listener would see, so `check` compares each snapshot with the last
one (every second or so). Comparing is cheap because robot states are immutable and shared: a robot
that only republished keeps its components mapping and its (usually empty, shared) missing set.

A robot that stops publishing gives one `robot_down` event at `robot_timeout`; its components going
STALE with it are implied, not recorded one by one. A component missing from messages its robot still
sends gives `missing`, then `level` → STALE at `stale_after`, and `appeared` when it is reported again.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass

from overseer.history.events import Event
from overseer.levels import Level, worst
from overseer.model import Component, ComponentKey, FleetLimits, FleetSnapshot, LevelChange, RobotState

EventSink = Callable[[list[Event]], None]


@dataclass(slots=True)
class _Seen:
    """What the last check saw of one robot."""

    heard: bool
    up: bool
    last_message: float | None
    components: Mapping[ComponentKey, Component]
    missing: frozenset[ComponentKey]
    stale: frozenset[ComponentKey]  # missing components already reported STALE


_NONE: frozenset[ComponentKey] = frozenset()


class TransitionDetector:
    """Detects transitions and hands them, in batches, to a sink (the event store)."""

    def __init__(self, limits: FleetLimits, sink: EventSink) -> None:
        """Judge staleness and robot timeouts by `limits`; send events to `sink`."""
        self._limits = limits
        self._sink = sink
        self._seen: dict[str, _Seen] = {}

    def on_level_changes(self, robot: str, at: float, changes: list[LevelChange]) -> None:
        """The model's level listener: one event per reported level change or new component."""
        events = []
        for previous, current in changes:
            events.append(
                Event(
                    at,
                    robot,
                    "appeared" if previous is None else "level",
                    current.key[0],
                    current.key[1],
                    None if previous is None else previous.level,
                    current.level,
                    current.message,
                    current.values,
                )
            )
        self._sink(events)

    def check(self, snapshot: FleetSnapshot) -> None:
        """Compare `snapshot` with the last one checked and send the transitions time brought."""
        events: list[Event] = []
        seen = self._seen
        present = set()
        for robot in snapshot.robots:
            present.add(robot.name)
            before = seen.get(robot.name)
            up = snapshot.robot_up(robot)
            if before is None:
                before = _Seen(False, False, None, robot.components, robot.missing, _NONE)
                seen[robot.name] = before
            self._robot_transitions(snapshot, robot, before, up, events)
        for name in [name for name in seen if name not in present]:
            del seen[name]
            events.append(
                Event(
                    snapshot.taken_at,
                    name,
                    "expired",
                    message=f"forgotten after {self._limits.expire_after:g} s of silence",
                )
            )
        if events:
            self._sink(events)

    def _robot_transitions(
        self, snapshot: FleetSnapshot, robot: RobotState, before: _Seen, up: bool, events: list[Event]
    ) -> None:
        limits = self._limits
        name = robot.name
        if before.up and not up:
            last = robot.last_message if robot.last_message is not None else snapshot.taken_at
            events.append(
                Event(
                    last + limits.robot_timeout,
                    name,
                    "robot_down",
                    old_level=_reported_worst(before.components),
                    new_level=Level.STALE,
                    message=f"no diagnostics received for {limits.robot_timeout:g} s",
                )
            )
        elif up and not before.up:
            events.append(
                Event(
                    robot.last_message if robot.last_message is not None else snapshot.taken_at,
                    name,
                    "robot_up",
                    old_level=Level.STALE if before.heard else None,
                    new_level=snapshot.robot_level(robot),
                    message="diagnostics received again" if before.heard else "first diagnostics received",
                )
            )
        stale = before.stale
        if up and (robot.missing or before.missing):
            stale = self._missing_transitions(snapshot, robot, before, events)
        components = robot.components
        if components is not before.components and not before.components.keys() <= components.keys():
            for key, component in before.components.items():
                if key not in components:
                    events.append(
                        Event(
                            snapshot.taken_at,
                            name,
                            "expired",
                            key[0],
                            key[1],
                            old_level=component.level,
                            message=f"forgotten after {limits.expire_after:g} s of silence",
                        )
                    )
        before.heard = before.heard or robot.last_message is not None
        before.up = up
        before.last_message = robot.last_message
        before.components = components
        before.missing = robot.missing
        before.stale = stale.intersection(robot.missing) if stale else _NONE

    def _missing_transitions(
        self, snapshot: FleetSnapshot, robot: RobotState, before: _Seen, events: list[Event]
    ) -> frozenset[ComponentKey]:
        """Events of components leaving or re-entering the robot's messages; the ones now STALE."""
        name = robot.name
        at = robot.last_message if robot.last_message is not None else snapshot.taken_at
        components = robot.components
        missing = robot.missing
        if missing != before.missing:
            for key in missing - before.missing:
                component = components.get(key)
                if component is not None:
                    events.append(
                        Event(
                            at,
                            name,
                            "missing",
                            key[0],
                            key[1],
                            old_level=component.level,
                            message="not in the robot's latest message",
                        )
                    )
            for key in before.missing - missing:
                component = components.get(key)
                if component is not None:
                    events.append(
                        Event(
                            at,
                            name,
                            "appeared",
                            key[0],
                            key[1],
                            new_level=component.level,
                            message=component.message,
                            values=component.values,
                        )
                    )
        stale = set(before.stale)
        stale_after = self._limits.stale_after
        for key in missing:
            component = components.get(key)
            if component is None or key in stale:
                continue
            updated = snapshot.last_update(robot, key, component)
            if not snapshot.fresh(updated):
                stale.add(key)
                events.append(
                    Event(
                        updated + stale_after,
                        name,
                        "level",
                        key[0],
                        key[1],
                        old_level=component.level,
                        new_level=Level.STALE,
                        message=f"not reported for {stale_after:g} s",
                    )
                )
        return frozenset(stale)


def _reported_worst(components: Mapping[ComponentKey, Component]) -> Level:
    return worst(component.level for component in components.values())
