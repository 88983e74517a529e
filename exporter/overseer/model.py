"""The live fleet model: robot → component → level, message, hardware_id, key-values, last update.

Writers (the transports) call `apply` with decoded arrays; readers (the views) take a `FleetSnapshot`.
Robot states are immutable and replaced whole on every message, so a snapshot is a shallow copy taken
under the one lock, and views read it with no lock held. Staleness and robot up/down are derived from
the snapshot's time, never stored, so they cannot drift from the clock.
"""

from __future__ import annotations

import sys
import threading
import time
from collections import Counter
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import NamedTuple

from overseer.levels import Level, worst
from overseer.messages import DiagnosticArray, DiagnosticStatus

ComponentKey = tuple[str, str]  # (name, hardware_id)
_LEVELS = tuple(Level)  # by wire value, faster than calling the enum


@dataclass(frozen=True)
class FleetLimits:
    """Time limits and caps that bound what the model keeps."""

    stale_after: float = 5.0
    robot_timeout: float = 10.0
    expire_after: float = 3600.0
    max_robots: int = 10_000
    max_components_per_robot: int = 1_000
    max_values_per_component: int = 64
    max_string_length: int = 1_024


class Component(NamedTuple):
    """The last status a component reported; `level` is the reported level, before staleness.

    `last_update` is when it was last reported in a message other than its robot's latest one; while it
    is in the latest message, `FleetSnapshot.last_update` gives that message's time instead. This lets
    an unchanged message refresh a whole robot by replacing one `RobotState`. A named tuple, not a frozen
    dataclass: it is built for every status that changed, and a frozen dataclass is four times slower
    to build. `key` is the very tuple that keys it in its robot's components (and in `latest`).
    """

    key: ComponentKey
    level: Level
    message: str
    values: tuple[tuple[str, str], ...]
    last_update: float
    level_changes: int
    topic: str

    @property
    def name(self) -> str:
        """The status's name."""
        return self.key[0]

    @property
    def hardware_id(self) -> str:
        """The status's hardware_id."""
        return self.key[1]


@dataclass(frozen=True, slots=True)
class RobotState:
    """One robot as last seen; replaced whole, never mutated.

    `latest` holds, in the message's order, the component each status of the latest message went to,
    or None where the status lost something (dropped, cut short, or a repeated name): an ingest may
    then apply only the statuses that changed (`FleetModel.apply_changes`). `missing` holds the
    components absent from the latest message; it is empty for almost every robot, so it is shared.
    """

    name: str
    transport: str
    last_message: float | None
    components: Mapping[ComponentKey, Component]
    discovered_at: float
    revision: int = 0
    latest: tuple[ComponentKey | None, ...] = ()
    missing: frozenset[ComponentKey] = frozenset()

    @property
    def last_seen(self) -> float:
        """When the robot last sent a message, or when it was discovered if it never did."""
        return self.discovered_at if self.last_message is None else self.last_message


class Applied(NamedTuple):
    """What applying one array did: whether nothing was dropped, and the robot's revision after it."""

    complete: bool
    revision: int | None  # None when the robot was refused (the robot cap)


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
        """True while the robot's messages arrive within `robot_timeout`."""
        return (
            robot.last_message is not None and self.taken_at - robot.last_message <= self.limits.robot_timeout
        )

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
        return updated is not None and self.taken_at - updated <= self.limits.stale_after

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


class FleetModel:
    """The fleet's live state behind one lock; safe to feed from many transport threads."""

    def __init__(self, limits: FleetLimits | None = None, clock: Callable[[], float] = time.time) -> None:
        """Create an empty fleet bounded by `limits`; `clock` gives unix time (injectable for tests)."""
        self.limits = limits or FleetLimits()
        self._clock = clock
        self._lock = threading.Lock()
        self._robots: dict[str, RobotState] = {}
        self._message_counts: Counter[tuple[str, str]] = Counter()
        self._dropped_statuses: Counter[str] = Counter()
        self._truncated_strings = 0
        self._source_errors: Counter[tuple[str, str]] = Counter()

    def count_source_error(self, transport: str, reason: str) -> None:
        """Count one failure of a transport to reach a robot (an unreachable master, a lost connection)."""
        with self._lock:
            self._source_errors[(transport, reason)] += 1

    def count_message(self, transport: str, result: str) -> None:
        """Count one message by its result (received, decode_error, dropped)."""
        with self._lock:
            self._message_counts[(transport, result)] += 1

    def register(self, robot: str, transport: str) -> bool:
        """Make a discovered robot known before its first message; False when the robot cap is reached."""
        with self._lock:
            if robot in self._robots:
                return True
            if len(self._robots) >= self.limits.max_robots:
                self._dropped_statuses["robot_limit"] += 1
                return False
            self._robots[robot] = RobotState(robot, transport, None, MappingProxyType({}), self._clock())
            return True

    def touch(self, robot: str, transport: str, revision: int | None = None) -> bool:
        """Record a message identical to the robot's last one; False when it must be applied in full.

        With `revision`, the robot must still be as that revision left it: anything else that changed
        it since (a forgotten topic, expired components) asks for a full apply too. So does a message
        that lost something, so that its losses are counted again each time it is received.
        """
        now = self._clock()
        with self._lock:
            state = self._robots.get(robot)
            if state is None or state.last_message is None or None in state.latest:
                return False
            if revision is not None and state.revision != revision:
                return False
            self._robots[robot] = RobotState(
                robot,
                transport,
                now,
                state.components,
                state.discovered_at,
                state.revision,
                state.latest,
                state.missing,
            )
            self._message_counts[(transport, "received")] += 1
        return True

    def apply(self, robot: str, array: DiagnosticArray, transport: str, topic: str = "") -> bool:
        """Merge one received array into the robot's state; False when anything in it was dropped."""
        return self.apply_array(robot, array, transport, topic).complete

    def apply_array(self, robot: str, array: DiagnosticArray, transport: str, topic: str = "") -> Applied:
        """Merge one received array into the robot's state, and tell the revision it made."""
        now = self._clock()
        limits = self.limits
        prepared, dropped, truncated = _prepare(array.statuses, limits)
        with self._lock:
            state = self._robots.get(robot)
            if state is None:
                if len(self._robots) >= limits.max_robots:
                    self._message_counts[(transport, "dropped")] += 1
                    self._dropped_statuses["robot_limit"] += len(array.statuses)
                    return Applied(False, None)
                components: dict[ComponentKey, Component] = {}
                revision, discovered_at = 0, now
            else:
                components = dict(state.components)
                revision, discovered_at = state.revision, state.discovered_at
            latest: list[ComponentKey | None] = []
            in_message: set[ComponentKey] = set()
            for entry in prepared:
                if entry is None:
                    latest.append(None)
                    continue
                key, level, message, values, intact = entry
                previous = components.get(key)
                if previous is None:
                    if len(components) >= limits.max_components_per_robot:
                        dropped["component_limit"] += 1
                        latest.append(None)
                        continue
                    previous = _component(_interned(key), level, message, values, now, 0, topic)
                    components[previous.key] = previous
                else:
                    components[key] = _merged(previous, level, message, values, now, topic)
                key = previous.key  # the fleet's shared copy, not this message's
                latest.append(key if intact and key not in in_message else None)
                in_message.add(key)
            if state is not None and state.last_message is not None:
                # Components missing from this message keep the time of the last message that had them.
                for key in state.components.keys() - state.missing - in_message:
                    left = components.get(key)
                    if left is not None:
                        components[key] = left._replace(last_update=state.last_message)
            missing = (
                _NONE_MISSING
                if len(in_message) == len(components)
                else frozenset(components.keys() - in_message)
            )
            self._robots[robot] = RobotState(
                robot,
                transport,
                now,
                MappingProxyType(components),
                discovered_at,
                revision + 1,
                tuple(latest),
                missing,
            )
            self._dropped_statuses.update(dropped)
            self._truncated_strings += truncated
            self._message_counts[(transport, "dropped" if dropped else "received")] += 1
        return Applied(not dropped, revision + 1)

    def apply_changes(
        self,
        robot: str,
        revision: int,
        changed: list[tuple[int, DiagnosticStatus]],
        transport: str,
        topic: str = "",
    ) -> int | None:
        """Apply an array equal to the robot's latest but for the statuses `changed` (by position).

        Only when the robot is still at `revision`, its latest message lost nothing, and every changed
        status kept its component; returns the new revision, or None (nothing done: apply it in full).
        """
        now = self._clock()
        prepared, dropped, truncated = _prepare([status for _, status in changed], self.limits)
        if dropped or truncated:
            return None
        with self._lock:
            state = self._robots.get(robot)
            if state is None or state.revision != revision or state.last_message is None:
                return None
            latest = state.latest
            if None in latest:
                return None
            merged: list[_Prepared] = []
            for (index, _), entry in zip(changed, prepared, strict=True):
                if entry is None or index >= len(latest) or latest[index] != entry[0]:
                    return None
                merged.append(entry)
            components = dict(state.components)
            for key, level, message, values, _intact in merged:
                components[key] = _merged(components[key], level, message, values, now, topic)
            self._robots[robot] = RobotState(
                robot,
                transport,
                now,
                MappingProxyType(components),
                state.discovered_at,
                revision + 1,
                latest,
                state.missing,
            )
            self._message_counts[(transport, "received")] += 1
        return revision + 1

    def forget_topic(self, robot: str, topic: str) -> None:
        """Drop the components a robot reported on `topic` (when it turns out to publish a better one)."""
        with self._lock:
            state = self._robots.get(robot)
            if state is None:
                return
            kept = {k: c for k, c in state.components.items() if c.topic != topic}
            if len(kept) != len(state.components):
                self._robots[robot] = _replace_components(state, kept)

    def expire(self) -> list[str]:
        """Forget robots and components silent for `expire_after`; returns the robots forgotten."""
        now = self._clock()
        horizon = now - self.limits.expire_after
        forgotten = []
        with self._lock:
            for name, state in list(self._robots.items()):
                if state.last_seen < horizon:
                    del self._robots[name]
                    forgotten.append(name)
                    continue
                last_update = FleetSnapshot.last_update
                if any(last_update(state, k, c) < horizon for k, c in state.components.items()):
                    kept = {k: c for k, c in state.components.items() if last_update(state, k, c) >= horizon}
                    self._robots[name] = _replace_components(state, kept)
        return forgotten

    def snapshot(self) -> FleetSnapshot:
        """An immutable copy of the fleet, taken now."""
        with self._lock:
            robots = tuple(self._robots.values())
            counts = dict(self._message_counts)
            dropped = dict(self._dropped_statuses)
            truncated = self._truncated_strings
            errors = dict(self._source_errors)
        return FleetSnapshot(self._clock(), self.limits, robots, counts, dropped, truncated, errors)


_NONE_MISSING: frozenset[ComponentKey] = frozenset()

# A status ready to merge: its component, level, message, values, and whether it arrived whole.
_Prepared = tuple[ComponentKey, Level, str, tuple[tuple[str, str], ...], bool]


def _prepare(
    statuses: Iterable[DiagnosticStatus], limits: FleetLimits
) -> tuple[list[_Prepared | None], Counter[str], int]:
    """Statuses checked and cut to the limits (None where dropped), what was dropped, strings cut."""
    max_length = limits.max_string_length
    max_values = limits.max_values_per_component
    truncated = 0
    prepared: list[_Prepared | None] = []
    dropped: Counter[str] = Counter()
    for wire_level, name, message, hardware_id, values in statuses:
        if not 0 <= wire_level <= 3:
            dropped["invalid_level"] += 1
            prepared.append(None)
            continue
        intact = True
        if len(name) > max_length or len(hardware_id) > max_length or len(message) > max_length:
            truncated += (
                (len(name) > max_length) + (len(hardware_id) > max_length) + (len(message) > max_length)
            )
            name, hardware_id, message = name[:max_length], hardware_id[:max_length], message[:max_length]
            intact = False
        if len(values) > max_values:
            dropped["value_limit"] += len(values) - max_values
            values = values[:max_values]
            intact = False
        for value_key, value_text in values:
            if len(value_key) > max_length or len(value_text) > max_length:
                truncated += sum((len(k) > max_length) + (len(v) > max_length) for k, v in values)
                values = tuple((k[:max_length], v[:max_length]) for k, v in values)
                intact = False
                break
        prepared.append(((name, hardware_id), _LEVELS[wire_level], message, values, intact))
    return prepared, dropped, truncated


def _component(
    key: ComponentKey,
    level: Level,
    message: str,
    values: tuple[tuple[str, str], ...],
    now: float,
    changes: int,
    topic: str,
) -> Component:
    # Robots of one fleet repeat the same messages and keys: interning stores each text once.
    intern = sys.intern
    return Component(
        key, level, intern(message), tuple([(intern(k), v) for k, v in values]), now, changes, topic
    )


def _merged(
    previous: Component,
    level: Level,
    message: str,
    values: tuple[tuple[str, str], ...],
    now: float,
    topic: str,
) -> Component:
    """The component's record after a status: `previous` itself when the status says nothing new."""
    if (
        previous.level is level
        and previous.message == message
        and previous.values == values
        and previous.topic == topic
    ):
        return previous
    changes = previous.level_changes + (previous.level is not level)
    return _component(previous.key, level, message, values, now, changes, topic)


def _interned(key: ComponentKey) -> ComponentKey:
    return sys.intern(key[0]), sys.intern(key[1])


def _replace_components(state: RobotState, components: dict[ComponentKey, Component]) -> RobotState:
    return RobotState(
        state.name,
        state.transport,
        state.last_message,
        MappingProxyType(components),
        state.discovered_at,
        state.revision + 1,
        tuple(key if key in components else None for key in state.latest),
        state.missing.intersection(components),
    )
