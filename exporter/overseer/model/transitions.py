"""Turns the fleet's changes into events: a hook for what robots report, a diff for what time decides.

Reported level changes come from the model's level listener, called as each message is applied: every
change is seen with its exact message and time, even one that flips back within a second, and it costs
nothing while levels hold. What time decides (a robot down or up again, a component that stopped being
updated or came back, one forgotten) follows from comparing each snapshot with the last one (every second
or so). Comparing is cheap: a robot whose components are all fresh, up as before, has nothing to judge.

A robot that stops publishing gives one `robot_down` event when it goes down; its components going STALE
with it are implied, not recorded one by one. A component of a robot still heard gives `missing` when it
passes its bound without an update (it went STALE while the robot spoke on), never because one array left
it out (several nodes share a robot's `/diagnostics`, each with its own statuses), and `appeared` when it
is new or updated again after being missing, or `expired` when the model forgets it. Every event carries
the wall-clock time it happened at, as the robot's messages dated it.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

from overseer.levels import Level, worst
from overseer.model.events import Event, EventSink
from overseer.model.fleet import LevelChange
from overseer.model.inventory import EXPECTED_FEED
from overseer.model.snapshot import FleetSnapshot, RobotTiming
from overseer.model.state import (
    Component,
    ComponentKey,
    FleetLimits,
    Forgetting,
    RobotState,
    robot_timeout,
)


@dataclass(slots=True)
class _Seen:
    """What the last check saw of one robot.

    Nothing here holds a robot's components mapping: a mapping kept a second longer than the model
    keeps it survives into the garbage collector's older generations, and at 1,000 robots changing
    every second that doubled the cost of applying messages.
    """

    discovered_at: float  # which robot of that name: one forgotten and followed again is another
    heard: bool
    up: bool
    up_since: float  # the robot's run of messages at the last check (it starts anew after being down)
    last_message: float  # the robot's last message at the last check
    revision: int
    timing: RobotTiming | None
    stale: dict[ComponentKey, tuple[Level, str]]  # STALE while their robot is up: level, hardware_id


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
                    current.hardware_id,
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
        robot_up = snapshot.robot_up
        known = 0  # robots of the snapshot seen before: fewer than `seen` holds means some are gone
        for robot in snapshot.robots:
            before = seen.get(robot.name)
            up = robot_up(robot)
            if before is None or before.discovered_at != robot.discovered_at:
                if before is not None:  # forgotten and followed again since the last check: it ended
                    known += 1
                    ended = self._forgotten(snapshot, robot.name, before.heard)
                    if ended is not None:
                        events.append(ended)
                before = seen[robot.name] = _first_seen(robot, up)
            else:
                known += 1
            if before.revision != robot.revision or before.timing is None:
                before.timing = snapshot.timing(robot)
                before.revision = robot.revision
            if (
                up is before.up
                and robot.up_since == before.up_since
                and not before.stale
                and not any(snapshot.staleness(robot, before.timing))
            ):
                continue  # the common case: a robot up (or down) as before, every component fresh
            self._robot_transitions(snapshot, robot, before, up, events)
        if known < len(seen) - (len(snapshot.robots) - known):
            present = {robot.name for robot in snapshot.robots}
            for name in [name for name in seen if name not in present]:
                event = self._forgotten(snapshot, name, seen.pop(name).heard)
                if event is not None:
                    events.append(event)
        if events:
            self._sink(events)

    def _forgotten(self, snapshot: FleetSnapshot, name: str, heard: bool) -> Event | None:
        """The event of a robot the model forgot, or None.

        A retirement is recorded where it is asked for (with its author); a robot discovered but never
        heard, and never listed, had no event before and gets none now.
        """
        forgetting = snapshot.forgotten.get(name) or Forgetting("expired", snapshot.generated_at)
        reason, at = forgetting
        if reason == "retired" or (reason == "expired" and not heard):
            return None
        if reason == "unlisted":
            message = "removed from the inventory"
        elif reason == "reattributed":
            message = "its publisher turned out to be another robot's node"
        else:
            message = f"forgotten after {self._limits.expire_after:g} s of silence"
        return Event(at, name, reason, message=message)

    def _robot_transitions(
        self, snapshot: FleetSnapshot, robot: RobotState, before: _Seen, up: bool, events: list[Event]
    ) -> None:
        """A robot's downs and ups since the last check, each at its time.

        A new run of messages (`up_since` moved) means the robot was down in between, even when both
        happened between two checks: a run that began and ended since then is an up and a down.
        """
        new_run = robot.last_message is not None and robot.up_since != before.up_since
        left_at = robot.left_at
        if before.up and new_run:  # down and back between two checks
            if left_at is not None and left_at <= robot.up_since:
                events.append(self._down(robot, robot.wall_time(left_at), True))
            else:  # silent since about the last check
                silent_until = before.last_message + robot_timeout(self._limits, robot)
                events.append(self._down(robot, robot.wall_time(min(silent_until, robot.up_since)), False))
        elif before.up and not up:
            events.append(
                self._down(robot, robot.wall_time(snapshot.went_down_at(robot)), not robot.publisher_alive)
            )
        if new_run:
            events.append(
                Event(
                    robot.wall_time(robot.up_since),
                    robot.name,
                    "robot_up",
                    old_level=Level.STALE if before.heard else None,
                    new_level=snapshot.robot_level(robot) if up else _reported_worst(robot.components),
                    message="diagnostics received again" if before.heard else "first diagnostics received",
                )
            )
            if not up:  # its run ended already
                down_at = robot.wall_time(snapshot.went_down_at(robot))
                events.append(self._down(robot, down_at, not robot.publisher_alive))
        if up:
            self._component_transitions(snapshot, robot, before, events)
        before.heard = before.heard or robot.last_message is not None
        before.up = up
        before.up_since = robot.up_since
        before.last_message = robot.last_message or 0.0

    def _down(self, robot: RobotState, at: float, left: bool) -> Event:
        """`robot_down` at `at`, because its publisher left or because it fell silent."""
        return Event(
            at,
            robot.name,
            "robot_down",
            old_level=_reported_worst(robot.components),  # unchanged since it went silent
            new_level=Level.STALE,
            message="its diagnostics publisher left"
            if left
            else f"no diagnostics received for {robot_timeout(self._limits, robot):g} s",
        )

    def _component_transitions(
        self, snapshot: FleetSnapshot, robot: RobotState, before: _Seen, events: list[Event]
    ) -> None:
        """Components of a robot that is up going STALE, updated again, or forgotten while STALE."""
        name, components = robot.name, robot.components
        stale = before.stale
        for key, (level, hardware_id) in list(stale.items()):
            component = components.get(key)
            if component is None:  # expiry forgets only components that stopped being updated
                del stale[key]
                events.append(
                    Event(
                        snapshot.generated_at,
                        name,
                        "expired",
                        key[0],
                        hardware_id,
                        old_level=level,
                        message=f"forgotten after {self._limits.expire_after:g} s without an update",
                    )
                )
            elif snapshot.fresh(robot, key, component):
                del stale[key]
                events.append(
                    Event(
                        robot.wall_time(snapshot.last_update(robot, key, component)),
                        name,
                        "appeared",
                        key[0],
                        component.hardware_id,
                        new_level=component.level,
                        message=component.message,
                        values=component.values,
                    )
                )
        if not any(snapshot.staleness(robot, before.timing or snapshot.timing(robot))):
            return
        last_message = robot.last_message or 0.0
        for key, component in components.items():
            if key in stale or component.feed == EXPECTED_FEED or snapshot.fresh(robot, key, component):
                continue  # a stand-in for an unmet expectation is STALE from the start: nothing happens
            went_stale_at = snapshot.went_stale_at(robot, key, component)
            if last_message <= went_stale_at:
                continue  # the whole robot fell silent: that is its robot_down, not each component's
            stale[key] = (component.level, component.hardware_id)
            events.append(
                Event(
                    robot.wall_time(went_stale_at),
                    name,
                    "missing",
                    key[0],
                    component.hardware_id,
                    old_level=component.level,
                    new_level=Level.STALE,
                    message=f"not updated for {snapshot.stale_after(robot, component):g} s",
                )
            )


def _first_seen(robot: RobotState, up: bool) -> _Seen:
    """What the detector knows of a robot it sees for the first time.

    A robot remembered from before this start (heard then, on no feed yet now) is taken as it was: no
    event says it came up, and its next message continues its run or begins a new one as it would have.
    """
    if robot.last_message is not None and not robot.feeds:
        return _Seen(robot.discovered_at, True, up, robot.up_since, robot.last_message, -1, None, {})
    return _Seen(robot.discovered_at, False, False, -1.0, 0.0, -1, None, {})


def _reported_worst(components: Mapping[ComponentKey, Component]) -> Level:
    return worst(component.level for component in components.values())
