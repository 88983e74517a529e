"""The live fleet model: robot → component → level, message, hardware_id, key-values, last update.

Writers (the transports) call `apply` with decoded arrays; readers (the views) take a `FleetSnapshot`.
Robot states are replaced whole on every message, so a snapshot is a shallow copy taken under the one
lock, and views read it with no lock held.
"""

from __future__ import annotations

import sys
import threading
import time
from collections import Counter
from collections.abc import Callable, Iterable
from dataclasses import replace
from types import MappingProxyType
from typing import NamedTuple

from overseer.levels import Level
from overseer.messages import DiagnosticArray, DiagnosticStatus
from overseer.model.snapshot import FleetSnapshot
from overseer.model.state import Component, ComponentKey, FleetLimits, RobotState

_LEVELS = tuple(Level)  # by wire value, faster than calling the enum


class Applied(NamedTuple):
    """What applying one array did: whether nothing was dropped, and the robot's revision after it."""

    complete: bool
    revision: int | None  # None when the robot was refused (the robot cap)


class LevelChange(NamedTuple):
    """A component whose reported level changed in one message (`previous` None: first reported)."""

    previous: Component | None
    current: Component


# Called after the lock is released with the robot, the message's time and what changed in it.
LevelListener = Callable[[str, float, list[LevelChange]], None]


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
        self._level_listener: LevelListener | None = None

    def set_level_listener(self, listener: LevelListener | None) -> None:
        """Have `listener` told of every reported level change and every new component, as applied."""
        self._level_listener = listener

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
                state.publisher_alive,
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
        listener = self._level_listener
        changes: list[LevelChange] | None = [] if listener is not None else None
        with self._lock:
            state = self._robots.get(robot)
            if state is None:
                if len(self._robots) >= limits.max_robots:
                    self._message_counts[(transport, "dropped")] += 1
                    self._dropped_statuses["robot_limit"] += len(array.statuses)
                    return Applied(False, None)
                components: dict[ComponentKey, Component] = {}
                revision, discovered_at, alive = 0, now, True
            else:
                components = dict(state.components)
                revision, discovered_at, alive = state.revision, state.discovered_at, state.publisher_alive
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
                    if changes is not None:
                        changes.append(LevelChange(None, previous))
                else:
                    merged = components[key] = _merged(previous, level, message, values, now, topic)
                    if changes is not None and merged.level is not previous.level:
                        changes.append(LevelChange(previous, merged))
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
                alive,
            )
            self._dropped_statuses.update(dropped)
            self._truncated_strings += truncated
            self._message_counts[(transport, "dropped" if dropped else "received")] += 1
        if changes and listener is not None:
            listener(robot, now, changes)
        return Applied(not dropped, revision + 1)

    def apply_changes(
        self,
        robot: str,
        revision: int,
        changed: list[tuple[int, DiagnosticStatus]],
        transport: str,
        topic: str = "",
        *,
        fits_limits: bool = False,
    ) -> int | None:
        """Apply an array equal to the robot's latest but for the statuses `changed` (by position).

        Only when the robot is still at `revision`, its latest message lost nothing, and every changed
        status kept its component; returns the new revision, or None (nothing done: apply it in full).
        `fits_limits`: the caller has checked that no status has a level outside 0-3, a text longer
        than `max_string_length` or more than `max_values_per_component` key-values.
        """
        now = self._clock()
        if not fits_limits and not _intact(changed, self.limits):
            return None
        with self._lock:
            state = self._robots.get(robot)
            if state is None or state.revision != revision or state.last_message is None:
                return None
            latest = state.latest
            if None in latest:
                return None
            in_latest = len(latest)
            components = dict(state.components)
            listener = self._level_listener
            changes: list[LevelChange] = []
            intern = sys.intern
            # Written for speed (arrays that changed in every status come through here): the checks and
            # the merge of `_prepare` and `_merged`, on statuses `_intact` found within every limit.
            for index, (wire_level, name, message, hardware_id, values) in changed:
                if index >= in_latest:
                    return None
                key = latest[index]
                if key is None or key[0] != name or key[1] != hardware_id:
                    return None
                previous = components[key]
                level = _LEVELS[wire_level]
                same_values = previous.values == values
                if (
                    previous.level is level
                    and previous.message == message
                    and same_values
                    and previous.topic == topic
                ):
                    continue  # the status says nothing new
                current = components[key] = Component(
                    previous.key,
                    level,
                    intern(message),
                    previous.values if same_values else tuple([(intern(k), v) for k, v in values]),
                    now,
                    previous.level_changes + (previous.level is not level),
                    topic,
                )
                if listener is not None and current.level is not previous.level:
                    changes.append(LevelChange(previous, current))
            self._robots[robot] = RobotState(
                robot,
                transport,
                now,
                MappingProxyType(components),
                state.discovered_at,
                revision + 1,
                latest,
                state.missing,
                state.publisher_alive,
            )
            self._message_counts[(transport, "received")] += 1
        if changes and listener is not None:
            listener(robot, now, changes)
        return revision + 1

    def set_publisher_alive(self, robot: str, alive: bool) -> None:
        """Record that the robot's diagnostics publisher is alive or gone (no-op for an unknown robot)."""
        with self._lock:
            state = self._robots.get(robot)
            if state is not None and state.publisher_alive is not alive:
                self._robots[robot] = replace(state, publisher_alive=alive)

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


def _intact(changed: list[tuple[int, DiagnosticStatus]], limits: FleetLimits) -> bool:
    """Whether every status has a valid level and fits every limit, so that nothing of it would be lost."""
    max_length = limits.max_string_length
    max_values = limits.max_values_per_component
    for _, (wire_level, name, message, hardware_id, values) in changed:
        if (
            not 0 <= wire_level <= 3
            or len(message) > max_length
            or len(name) > max_length
            or len(hardware_id) > max_length
            or len(values) > max_values
        ):
            return False
        for value_key, value_text in values:
            if len(value_key) > max_length or len(value_text) > max_length:
                return False
    return True


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
        state.publisher_alive,
    )
