"""Turns the fleet's changes into events: a hook for what robots report, a diff for what time decides.

Reported level changes come from the model's level listener, called as each message is applied: every
change is seen with its exact message and time, even one that flips back within a second, and it costs
nothing while levels hold. STALE, robot down and up, missing and expired follow from time or from
messages that changed nothing a listener would see, so `check` compares each snapshot with the last
one (every second or so). Comparing is cheap: a robot that is up, as before, and reports every one of
its components (the model's shared empty missing set) has nothing to judge.

A robot that stops publishing gives one `robot_down` event at `robot_timeout`; its components going
STALE with it are implied, not recorded one by one. A component missing from messages its robot still
sends gives `missing`, then `level` → STALE at `stale_after`, and `appeared` when it is reported again
or `expired` when the model forgets it (only such components expire while their robot lives).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

from overseer.levels import Level, worst
from overseer.model.events import Event, EventSink
from overseer.model.fleet import LevelChange
from overseer.model.snapshot import FleetSnapshot
from overseer.model.state import Component, ComponentKey, FleetLimits, RobotState


@dataclass(slots=True)
class _Seen:
    """What the last check saw of one robot.

    Nothing here holds a robot's components mapping: a mapping kept a second longer than the model
    keeps it survives into the garbage collector's older generations, and at 1,000 robots changing
    every second that doubled the cost of applying messages.
    """

    heard: bool
    up: bool
    missing: frozenset[ComponentKey]  # the model's own set (usually its one shared empty set)
    missing_levels: dict[ComponentKey, Level]  # the reported level of each missing component
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
        taken_at = snapshot.taken_at
        robot_up = snapshot.robot_up
        for robot in snapshot.robots:
            before = seen.get(robot.name)
            up = robot_up(robot)
            if before is None:
                before = seen[robot.name] = _Seen(False, False, _NONE, {}, _NONE)
            elif up is before.up and not robot.missing and not before.missing:
                continue  # the common case: a robot up (or down) as before, reporting all its components
            self._robot_transitions(snapshot, robot, before, up, events)
        if len(seen) > len(snapshot.robots):
            present = {robot.name for robot in snapshot.robots}
            for name in [name for name in seen if name not in present]:
                if not seen.pop(name).heard:
                    continue  # discovered but never heard from: it never had an event either
                events.append(
                    Event(
                        taken_at,
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
        last = robot.last_message if robot.last_message is not None else snapshot.taken_at
        if before.up and not up:
            left = not robot.publisher_alive  # the transport saw its publisher go: down now, not later
            events.append(
                Event(
                    snapshot.went_down_at(robot),
                    name,
                    "robot_down",
                    old_level=_reported_worst(robot.components),  # unchanged since it went silent
                    new_level=Level.STALE,
                    message="its diagnostics publisher left"
                    if left
                    else f"no diagnostics received for {limits.robot_timeout:g} s",
                )
            )
        elif up and not before.up:
            events.append(
                Event(
                    last,
                    name,
                    "robot_up",
                    old_level=Level.STALE if before.heard else None,
                    new_level=snapshot.robot_level(robot),
                    message="diagnostics received again" if before.heard else "first diagnostics received",
                )
            )
        if up and (robot.missing or before.missing):
            self._missing_transitions(snapshot, robot, before, events)
        before.heard = before.heard or robot.last_message is not None
        before.up = up

    def _missing_transitions(
        self, snapshot: FleetSnapshot, robot: RobotState, before: _Seen, events: list[Event]
    ) -> None:
        """Components leaving the robot's messages, going STALE, coming back, or forgotten while away."""
        name, limits = robot.name, self._limits
        at = robot.last_message if robot.last_message is not None else snapshot.taken_at
        components, missing = robot.components, robot.missing
        levels = before.missing_levels
        if missing != before.missing:
            for key in missing - before.missing:
                component = components.get(key)
                if component is not None:
                    levels[key] = component.level
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
                level = levels.pop(key, None)
                if component is None:  # expiry forgets only components that stopped being reported
                    events.append(
                        Event(
                            snapshot.taken_at,
                            name,
                            "expired",
                            key[0],
                            key[1],
                            old_level=level,
                            message=f"forgotten after {limits.expire_after:g} s of silence",
                        )
                    )
                else:
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
        stale = set(before.stale.intersection(missing))
        for key in missing:
            component = components.get(key)
            if component is None or key in stale:
                continue
            updated = snapshot.last_update(robot, key, component)
            if not snapshot.fresh(updated):
                stale.add(key)
                events.append(
                    Event(
                        snapshot.went_stale_at(updated),
                        name,
                        "level",
                        key[0],
                        key[1],
                        old_level=component.level,
                        new_level=Level.STALE,
                        message=f"not reported for {limits.stale_after:g} s",
                    )
                )
        before.missing = missing
        before.stale = frozenset(stale) if stale else _NONE


def _reported_worst(components: Mapping[ComponentKey, Component]) -> Level:
    return worst(component.level for component in components.values())
