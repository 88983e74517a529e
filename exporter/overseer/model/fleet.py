"""The live fleet model: robot → component → level, message, hardware_id, key-values, last update.

Writers (the transports) call `apply` with decoded arrays; readers (the views) take a `FleetSnapshot`.
Robot states are replaced whole on every message, so a snapshot is a shallow copy taken under the one
lock, and views read it with no lock held.

A robot is heard on feeds: a topic, or one publisher of a topic where the transport tells publishers
apart. Each feed's arrays may hold only some of the robot's components (several diagnostic_updater nodes
share one robot's `/diagnostics`, and a node's start-up array holds one status); a component is whatever
its robot reports under one name (`state.ComponentKey`), whichever feed reported it last.
"""

from __future__ import annotations

import threading
import time
from collections import Counter
from collections.abc import Callable, Iterable
from types import MappingProxyType
from typing import NamedTuple

from overseer.levels import Level
from overseer.messages import DiagnosticArray, DiagnosticStatus
from overseer.model.component_keys import ComponentKeys
from overseer.model.inventory import (
    EXPECTED_FEED,
    Inventory,
    expected_components,
    is_stand_in,
    listed_state,
    restored_components,
)
from overseer.model.robot_cap import RobotCap
from overseer.model.snapshot import FleetSnapshot
from overseer.model.state import (
    PERIOD_SAMPLES,
    Component,
    ComponentKey,
    Feed,
    FleetLimits,
    ForgetReason,
    Forgetting,
    RememberedRobot,
    RobotState,
    feed_stale_after,
    robot_timeout,
    steady_wall_offset,
    up_since,
)

_LEVELS = tuple(Level)  # by wire value, faster than calling the enum


class Applied(NamedTuple):
    """What applying one array did: whether nothing was dropped, and the feed's revision after it."""

    complete: bool
    revision: int | None  # None when the array was refused (the robot cap, the feed cap)


class LevelChange(NamedTuple):
    """A component whose reported level changed in one message (`previous` None: first reported)."""

    previous: Component | None
    current: Component


# Called after the lock is released with the robot, the message's wall-clock time and what changed in it.
LevelListener = Callable[[str, float, list[LevelChange]], None]


class FleetModel:
    """The fleet's live state behind one lock; safe to feed from many transport threads."""

    def __init__(
        self,
        limits: FleetLimits | None = None,
        clock: Callable[[], float] | None = None,
        wall_clock: Callable[[], float] | None = None,
        robot_cap: RobotCap | None = None,
    ) -> None:
        """Create an empty fleet bounded by `limits`.

        `clock` (default: monotonic) judges ages and `wall_clock` (default: the system's, or `clock` when
        only that is given, as tests do) dates what is reported. `robot_cap` (default: `limits.max_robots`
        in this model alone) says whether a new robot fits.
        """
        self.limits = limits or FleetLimits()
        self._robot_cap = RobotCap(self.limits.max_robots) if robot_cap is None else robot_cap
        self._clock = time.monotonic if clock is None else clock
        self._wall_clock = wall_clock or (time.time if clock is None else clock)
        self._lock = threading.Lock()
        self._robots: dict[str, RobotState] = {}
        self._message_counts: Counter[tuple[str, str]] = Counter()
        self._dropped_statuses: Counter[str] = Counter()
        self._truncated_strings = 0
        self._source_errors: Counter[tuple[str, str]] = Counter()
        self._level_listener: LevelListener | None = None
        # Held from the end of an apply (taken under `_lock`) until its listener has been told, so that
        # whoever saw the apply's result in a snapshot can wait for its events to be sent first.
        self._telling = threading.Lock()
        self._clashed: dict[str, set[str]] = {}  # robot → names it reports kept apart by hardware_id
        self._keys = ComponentKeys()
        self._forgotten: dict[str, Forgetting] = {}  # the robots forgotten last, oldest first, and why
        self._forgotten_counts: Counter[str] = Counter()

    def set_level_listener(self, listener: LevelListener | None) -> None:
        """Have `listener` told of every reported level change and every new component, as applied."""
        self._level_listener = listener

    def _tell(self, listener: LevelListener, robot: str, at: float, changes: list[LevelChange]) -> None:
        """Tell `listener` of an apply's changes, outside the model's lock, then let waiters on."""
        try:
            listener(robot, at, changes)
        finally:
            self._telling.release()

    def told_snapshot(self) -> FleetSnapshot:
        """A snapshot, returned once the level listener has been told of every change it shows.

        The event detector compares these: the events it derives (a robot up) then follow the events of
        the applies they saw (its components appearing), never overtake them.
        """
        snapshot = self.snapshot()
        with self._telling:  # an apply the snapshot shows took this before `_lock` was let go
            pass
        return snapshot

    def count_source_error(self, transport: str, reason: str) -> None:
        """Count one failure of a transport to reach a robot (an unreachable master, a lost connection)."""
        with self._lock:
            self._source_errors[(transport, reason)] += 1

    def count_message(self, transport: str, result: str, count: int = 1) -> None:
        """Count `count` messages by their result (received, decode_error, dropped, lost)."""
        with self._lock:
            self._message_counts[(transport, result)] += count

    def register(self, robot: str, transport: str) -> bool:
        """Make a discovered robot known before its first message; False when the robot cap is reached."""
        now, wall = self._clock(), self._wall_clock()
        with self._lock:
            if robot in self._robots:
                return True
            if not self._robot_cap.admit(len(self._robots)):
                self._dropped_statuses["robot_limit"] += 1
                return False
            self._robots[robot] = RobotState(
                robot, transport, None, MappingProxyType({}), now, wall_offset=wall - now
            )
            return True

    def touch(self, robot: str, transport: str, feed: str = "", revision: int | None = None) -> bool:
        """Record a message identical to the feed's last one; False when it must be applied in full.

        With `revision`, the feed must still be as that revision left it: anything else that changed it
        since (another feed taking a component over, expired components) asks for a full apply too. So
        does a message that lost something, so that its losses are counted again each time it is received.
        """
        now, wall = self._clock(), self._wall_clock()
        with self._lock:
            state = self._robots.get(robot)
            if state is None:
                return False
            feeds = state.feeds
            index = _feed_index(feeds, feed)
            if index is None:
                return False
            old = feeds[index]
            if not old.lossless or (revision is not None and old.revision != revision):
                return False
            current = _learned(old, now, True, old.revision)
            bound_changed = current.period != old.period and feed_stale_after(
                self.limits, current
            ) != feed_stale_after(self.limits, old)
            self._robots[robot] = RobotState(
                robot,
                transport,
                now,
                state.components,
                state.discovered_at,
                state.revision + bound_changed,
                (*feeds[:index], current, *feeds[index + 1 :]),
                state.missing,
                state.left_at,
                steady_wall_offset(state.wall_offset, now, wall),
                up_since(self.limits, state, now),
                state.listing,
                state.dropped_level_changes,
            )
            self._message_counts[(transport, "received")] += 1
        return True

    def apply(
        self, robot: str, array: DiagnosticArray, transport: str, topic: str = "", feed: str | None = None
    ) -> bool:
        """Merge one received array into the robot's state; False when anything in it was dropped."""
        return self.apply_array(robot, array, transport, topic, feed).complete

    def apply_array(
        self, robot: str, array: DiagnosticArray, transport: str, topic: str = "", feed: str | None = None
    ) -> Applied:
        """Merge one array received on `feed` (default: the topic) and tell the feed's revision it made."""
        now, wall = self._clock(), self._wall_clock()
        feed_name = topic if feed is None else feed
        limits = self.limits
        prepared, dropped, truncated = _prepare(array.statuses, limits)
        listener = self._level_listener
        changes: list[LevelChange] | None = [] if listener is not None else None
        with self._lock:
            state = self._robots.get(robot)
            if state is None:
                if not self._robot_cap.admit(len(self._robots)):
                    self._message_counts[(transport, "dropped")] += 1
                    self._dropped_statuses["robot_limit"] += len(array.statuses)
                    return Applied(False, None)
                state = RobotState(robot, transport, None, MappingProxyType({}), now)
            offset = steady_wall_offset(state.wall_offset, now, wall)
            wall = now + offset  # this message's events are dated as its robot's other times are
            feeds = list(state.feeds)
            position = _feed_index(state.feeds, feed_name)
            if position is None and len(feeds) >= limits.max_feeds_per_robot:
                self._message_counts[(transport, "dropped")] += 1
                self._dropped_statuses["feed_limit"] += len(array.statuses)
                return Applied(False, None)
            clashed = self._clashed.setdefault(robot, set())
            merge = _Merge(state, feed_name, now, limits, changes, clashed, self._keys)
            latest = merge.statuses(prepared, dropped)
            if position is None:
                new_feed = Feed(feed_name, topic, now, latest, lossless=None not in latest)
                feeds.append(new_feed)
            else:
                old_feed = feeds[position]
                merge.left_out(old_feed)
                learned = _learned(old_feed, now, old_feed.latest == latest, old_feed.revision)
                new_feed = learned.with_latest(latest, old_feed.revision + 1)
                feeds[position] = new_feed
            components = merge.components
            if merge.added and state.listing is not None:
                components = expected_components(state.listing, components, now)
            self._robots[robot] = RobotState(
                robot,
                transport,
                now,
                MappingProxyType(components),
                state.discovered_at,
                state.revision + 1,
                merge.other_feeds(feeds),
                merge.missing_set(),
                state.left_at,
                offset,
                up_since(limits, state, now),
                state.listing,
                state.dropped_level_changes + merge.dropped_level_changes,
            )
            self._dropped_statuses.update(dropped)
            self._truncated_strings += truncated
            self._message_counts[(transport, "dropped" if dropped else "received")] += 1
            if changes and listener is not None:
                self._telling.acquire()
        if changes and listener is not None:
            self._tell(listener, robot, wall, changes)
        return Applied(not dropped, new_feed.revision)

    def apply_changes(
        self,
        robot: str,
        revision: int,
        changed: list[tuple[int, DiagnosticStatus]],
        transport: str,
        feed: str = "",
        *,
        fits_limits: bool = False,
    ) -> int | None:
        """Apply an array equal to the feed's latest but for the statuses `changed` (by position).

        Only when the feed is still at `revision`, its latest message lost nothing, and every changed
        status kept its component; returns the feed's new revision, or None (nothing done: apply it in
        full). `fits_limits`: the caller has checked that no status has a level outside 0-3, a text longer
        than `max_string_length` or more than `max_values_per_component` key-values.
        """
        now, wall = self._clock(), self._wall_clock()
        if not fits_limits and not _intact(changed, self.limits):
            return None
        with self._lock:
            state = self._robots.get(robot)
            if state is None:
                return None
            feeds = state.feeds
            index = _feed_index(feeds, feed)
            if index is None:
                return None
            offset = steady_wall_offset(state.wall_offset, now, wall)
            wall = now + offset
            old = feeds[index]
            latest = old.latest
            if old.revision != revision or not old.lossless:
                return None
            in_latest = len(latest)
            components = state.components.copy()  # the dict's own copy, not one key at a time
            listener = self._level_listener
            changes: list[LevelChange] = []
            new = tuple.__new__
            # Written for speed (arrays that changed in every status come through here): the checks and
            # the merge of `_prepare` and `_Merge.status`, on statuses `_intact` found within every limit.
            for position, (wire_level, name, message, hardware_id, values) in changed:
                if position >= in_latest:
                    return None
                key = latest[position]
                if key is None or key[0] != name or (key[1] and key[1] != hardware_id):
                    return None
                previous = components[key]
                level = _LEVELS[wire_level]
                same_values = previous.values == values
                same_id = not hardware_id or hardware_id == previous.hardware_id
                if previous.level is level and previous.message == message and same_values and same_id:
                    continue  # the status says nothing new
                # tuple.__new__ builds the named tuple without the Python call of its own __new__.
                current = components[key] = new(
                    Component,
                    (
                        previous.key,
                        level,
                        message,  # interned by the decoder, as hardware_id and the keys are
                        previous.hardware_id if same_id else hardware_id,
                        previous.values if same_values else values,
                        now,
                        previous.level_changes + (previous.level is not level),
                        feed,
                    ),
                )
                if listener is not None and current.level is not previous.level:
                    changes.append(LevelChange(previous, current))
            current_feed = _learned(old, now, True, revision + 1)
            self._robots[robot] = RobotState(
                robot,
                transport,
                now,
                MappingProxyType(components),
                state.discovered_at,
                state.revision + 1,
                (*feeds[:index], current_feed, *feeds[index + 1 :]),
                state.missing,
                state.left_at,
                offset,
                up_since(self.limits, state, now),
                state.listing,
                state.dropped_level_changes,
            )
            self._message_counts[(transport, "received")] += 1
            if changes and listener is not None:
                self._telling.acquire()
        if changes and listener is not None:
            self._tell(listener, robot, wall, changes)
        return revision + 1

    def publisher_left(self, robot: str) -> None:
        """Record that the robot's last diagnostics publisher left: it is down until it speaks again."""
        now = self._clock()
        with self._lock:
            state = self._robots.get(robot)
            if state is not None and state.publisher_alive:
                self._robots[robot] = state._replace(left_at=now, revision=state.revision + 1)

    def forget_topic(self, robot: str, topic: str) -> None:
        """Drop the components a robot reported on `topic` (when it turns out to publish a better one)."""
        with self._lock:
            state = self._robots.get(robot)
            if state is None:
                return
            gone = {feed.name for feed in state.feeds if feed.topic == topic}
            if gone:
                kept = {k: c for k, c in state.components.items() if c.feed not in gone}
                self._robots[robot] = _replace_components(state, kept, self._clock())

    def forget_feed(self, robot: str, feed: str, last: bool) -> None:
        """Drop what one feed told of `robot`: its publisher turned out to be another robot's node.

        A robot the source hears through no other publisher (`last`), with no feed left and not listed, was
        only ever that publisher: it is forgotten. Otherwise, when `last`, it is down from now on.
        """
        now, wall = self._clock(), self._wall_clock()
        with self._lock:
            state = self._robots.get(robot)
            if state is None:
                return
            kept = {k: c for k, c in state.components.items() if c.feed != feed}
            state = _replace_components(state, kept, now)
            if last and not state.feeds and state.listing is None:
                del self._robots[robot]
                self._forget(robot, "reattributed", wall)
            elif last and state.publisher_alive:
                self._robots[robot] = state._replace(left_at=now)
            else:
                self._robots[robot] = state

    def expire(self) -> list[str]:
        """Forget robots and components silent for `expire_after`; returns the robots forgotten.

        A listed robot is never forgotten, nor a component its listing expects (nor a stand-in for one).
        """
        now, wall = self._clock(), self._wall_clock()
        horizon = now - self.limits.expire_after
        forgotten = []
        last_update = FleetSnapshot.last_update
        with self._lock:
            for name, state in list(self._robots.items()):
                listing = state.listing
                if state.last_seen < horizon and listing is None:
                    del self._robots[name]
                    self._forget(name, "expired", wall)
                    forgotten.append(name)
                    continue
                if any(last_update(state, k, c) < horizon for k, c in state.components.items()):
                    kept = {
                        key: component
                        for key, component in state.components.items()
                        if last_update(state, key, component) >= horizon
                        or (listing is not None and (is_stand_in(component) or listing.expects(key[0])))
                    }
                    if len(kept) < len(state.components):
                        self._robots[name] = _replace_components(state, kept, now)
        return forgotten

    def set_inventory(self, inventory: Inventory, owns: Callable[[str], bool] | None = None) -> None:
        """Follow the inventory's robots (those `owns` accepts) from now on, heard or not.

        Each is labelled and shows its expected components; a robot no longer listed is followed as a
        discovered one (forgotten at once if it was never heard, after `expire_after` otherwise).
        """
        now, wall = self._clock(), self._wall_clock()
        listed = {name: entry for name, entry in inventory.robots.items() if owns is None or owns(name)}
        with self._lock:
            for name, state in list(self._robots.items()):
                if state.listing is None or name in listed:
                    continue
                if state.last_message is None:
                    del self._robots[name]
                    self._forget(name, "unlisted", wall)
                else:
                    self._robots[name] = listed_state(state, None, now)
            for name, entry in listed.items():
                known = self._robots.get(name)
                if known is None:
                    known = RobotState(name, "", None, MappingProxyType({}), now, wall_offset=wall - now)
                if known.listing != entry:
                    self._robots[name] = listed_state(known, entry, now)
            self._robot_cap.holds(len(self._robots))  # listed robots are followed past the cap

    def remember(self, robots: Iterable[RememberedRobot]) -> None:
        """Robots heard before this start: each silent since it was last heard, until it speaks again."""
        now, wall = self._clock(), self._wall_clock()
        with self._lock:
            for name, transport, heard_at, down, remembered in robots:
                state = self._robots.get(name)
                if state is not None and state.last_message is not None:
                    continue  # heard already in this run
                if state is None and not self._robot_cap.admit(len(self._robots)):
                    self._dropped_statuses["robot_limit"] += 1
                    continue
                last = now - max(0.0, wall - heard_at)
                listing = None if state is None else state.listing
                restored = restored_components(remembered, last, self._keys)
                components = expected_components(listing, restored, now)
                self._robots[name] = RobotState(
                    name,
                    transport,
                    last,
                    MappingProxyType(components),
                    last,
                    left_at=last if down else None,  # down until a message arrives after it
                    wall_offset=wall - now,
                    up_since=last,
                    listing=listing,
                )

    def heard(self, with_components: bool = False) -> list[RememberedRobot]:
        """Every robot heard, in this run or before it: when it was last heard (unix time), if down now.

        `with_components` adds what each reported (for a clean stop: a fleet of thousands is a lot).
        """
        now = self._clock()
        limits = self.limits
        with self._lock:
            robots = [state for state in self._robots.values() if state.last_message is not None]
        return [
            RememberedRobot(
                state.name,
                state.transport,
                state.last_message + state.wall_offset,
                not state.publisher_alive or now - state.last_message > robot_timeout(limits, state),
                tuple(
                    (component.name, component.hardware_id, int(component.level), component.message)
                    for component in state.components.values()
                    if component.feed != EXPECTED_FEED
                )
                if with_components
                else (),
            )
            for state in robots
            if state.last_message is not None
        ]

    def retire(self, name: str) -> str:
        """Forget a robot that is down and not listed: 'retired', or why not: 'unknown', 'listed', 'up'."""
        now, wall = self._clock(), self._wall_clock()
        with self._lock:
            state = self._robots.get(name)
            if state is None:
                return "unknown"
            if state.listing is not None:
                return "listed"
            last = state.last_message
            if last is not None and state.publisher_alive and now - last <= robot_timeout(self.limits, state):
                return "up"
            del self._robots[name]
            self._forget(name, "retired", wall)
        return "retired"

    def _forget(self, name: str, reason: ForgetReason, wall: float) -> None:
        """Count and note a robot just dropped from `_robots` (under the lock), for the event detector."""
        self._robot_cap.holds(len(self._robots))
        self._clashed.pop(name, None)
        self._forgotten_counts[reason] += 1
        forgotten = self._forgotten
        forgotten[name] = Forgetting(reason, wall)
        if len(forgotten) > _FORGETTINGS_KEPT:
            del forgotten[next(iter(forgotten))]  # the oldest: the detector read it long ago

    def robots_snapshot(self, names: Iterable[str]) -> FleetSnapshot:
        """A snapshot holding only the robots named that are known, in that order, without the fleet's counts.

        What one robot's document, or the push's few robots a look, need: a whole snapshot copies every
        robot and every count (10,000 of each in a large fleet) for a page that shows one.
        """
        with self._lock:
            known = self._robots
            robots = tuple(robot for name in names if (robot := known.get(name)) is not None)
        return FleetSnapshot(self._clock(), self.limits, robots, generated_at=self._wall_clock())

    def snapshot(self) -> FleetSnapshot:
        """An immutable copy of the fleet, taken now."""
        with self._lock:
            robots = tuple(self._robots.values())
            counts = dict(self._message_counts)
            dropped = dict(self._dropped_statuses)
            truncated = self._truncated_strings
            errors = dict(self._source_errors)
            forgotten = dict(self._forgotten) if self._forgotten else _NONE_FORGOTTEN
            forgotten_counts = dict(self._forgotten_counts)
        return FleetSnapshot(
            self._clock(),
            self.limits,
            robots,
            counts,
            dropped,
            truncated,
            errors,
            self._wall_clock(),
            forgotten,
            forgotten_counts,
        )


class _Merge:
    """One full array of one feed merged into a robot's components (under the model's lock)."""

    def __init__(
        self,
        state: RobotState,
        feed: str,
        now: float,
        limits: FleetLimits,
        changes: list[LevelChange] | None,
        clashed: set[str],
        keys: ComponentKeys,
    ) -> None:
        self.components = state.components.copy()
        self._feed = feed
        self._now = now
        self._limits = limits
        self._changes = changes
        self._clashed = clashed  # the robot's names kept apart by hardware_id (the model's own set)
        self._keys = keys
        self._missing = set(state.missing)
        self._in_message: set[ComponentKey] = set()
        self.added = False  # a component the robot had not reported: its expectations are judged again
        self.dropped_level_changes = 0  # those of the components this message replaced
        self._taken_over: dict[str, set[ComponentKey]] = {}  # other feeds → the components taken from them

    def statuses(
        self, prepared: list[_Prepared | None], dropped: Counter[str]
    ) -> tuple[ComponentKey | None, ...]:
        """Merge every status of the array; the components they went to, in order (the feed's latest)."""
        components, limits, in_message = self.components, self._limits, self._in_message
        shared_key = self._keys.of
        first_ids = _clashes(prepared)
        for name in first_ids:
            if name not in self._clashed:  # kept apart from now on: the component under the name alone goes
                self._clashed.add(name)
                gone = components.pop((name, ""), None)
                if gone is not None:
                    self.dropped_level_changes += gone.level_changes
        latest: list[ComponentKey | None] = []
        for entry in prepared:
            if entry is None:
                latest.append(None)
                continue
            (name, hardware_id), level, message, values, intact = entry
            if name in self._clashed:
                key = self._kept_apart(name, hardware_id, first_ids)
            else:
                key = shared_key(name)
            previous = components.get(key)
            if previous is not None and previous.feed == EXPECTED_FEED:
                previous = None  # reported at last: a new component, in the stand-in's place
            if previous is None:
                self.added = True
                if len(components) >= limits.max_components_per_robot:
                    dropped["component_limit"] += 1
                    latest.append(None)
                    continue
                current = _component(key, level, message, hardware_id, values, self._now, 0, self._feed)
                if self._changes is not None:
                    self._changes.append(LevelChange(None, current))
            else:
                current = _merged(previous, level, message, hardware_id, values, self._now, self._feed)
                if self._changes is not None and current.level is not previous.level:
                    self._changes.append(LevelChange(previous, current))
                if previous.feed != self._feed:
                    self._taken_over.setdefault(previous.feed, set()).add(previous.key)
            components[current.key] = current
            key = current.key  # the fleet's shared copy, not this message's
            latest.append(key if intact and key not in in_message else None)
            in_message.add(key)
        self._missing.difference_update(in_message)
        return tuple(latest)

    def _kept_apart(self, name: str, hardware_id: str, first_ids: dict[str, str]) -> ComponentKey:
        """The component of a name kept apart by hardware_id; a status without one goes to the first."""
        if hardware_id:
            return (name, hardware_id)
        if name in first_ids:
            return (name, first_ids[name])
        for known in self.components:
            if known[0] == name:
                return known
        return (name, "")

    def left_out(self, old_feed: Feed) -> None:
        """What the feed's last message carried and this one does not keeps that message's time."""
        for key in old_feed.latest:
            if key is None or key in self._in_message or key in self._missing:
                continue
            component = self.components.get(key)
            if component is not None and component.feed == self._feed:
                self.components[key] = component._replace(last_update=old_feed.last_message)
                self._missing.add(key)

    def other_feeds(self, feeds: list[Feed]) -> tuple[Feed, ...]:
        """The feeds after this array, those that lost a component to it or carry nothing settled.

        One that lost a component reads its next message in full (its latest no longer says what it
        carries), and one left carrying nothing goes.
        """
        if not self._taken_over:
            return tuple(feeds)
        carried = {component.feed for component in self.components.values()} | {self._feed}
        settled = []
        for feed in feeds:
            if feed.name not in carried:
                continue
            taken = self._taken_over.get(feed.name)
            if taken:
                latest = tuple(None if key in taken else key for key in feed.latest)
                feed = feed.with_latest(latest, feed.revision + 1)
            settled.append(feed)
        return tuple(settled)

    def missing_set(self) -> frozenset[ComponentKey]:
        """The components not in their feed's latest message (the model's shared empty set for none)."""
        missing = self._missing
        missing.intersection_update(self.components)
        return frozenset(missing) if missing else _NONE_MISSING


_new_tuple = tuple.__new__  # builds a named tuple without the Python call of its own __new__
_NONE_MISSING: frozenset[ComponentKey] = frozenset()
_NONE_FORGOTTEN: dict[str, Forgetting] = {}
_FORGETTINGS_KEPT = 10_000  # enough for every robot forgotten between two checks of the detector

# A status ready to merge: its name and hardware_id, level, message, values, and whether it arrived whole.
_Prepared = tuple[tuple[str, str], Level, str, tuple[tuple[str, str], ...], bool]


def _clashes(prepared: list[_Prepared | None]) -> dict[str, str]:
    """The names an array holds more than once with different non-empty hardware_ids, with the first.

    Those names are kept apart by hardware_id from now on.
    """
    names = [entry[0][0] for entry in prepared if entry is not None]
    if len(set(names)) == len(names):
        return {}  # almost always: every name once
    hardware_ids: dict[str, list[str]] = {}
    for entry in prepared:
        if entry is not None and entry[0][1] and entry[0][1] not in hardware_ids.setdefault(entry[0][0], []):
            hardware_ids[entry[0][0]].append(entry[0][1])
    return {name: ids[0] for name, ids in hardware_ids.items() if len(ids) > 1}


def _feed_index(feeds: tuple[Feed, ...], name: str) -> int | None:
    """Where the feed called `name` is among `feeds`, or None."""
    for index, feed in enumerate(feeds):
        if feed.name == name:
            return index
    return None


def _learned(feed: Feed, now: float, same_components: bool, revision: int) -> Feed:
    """`feed` after a message at `now`, at `revision`, the interval learned when it carried what the last did.

    An interval under a quarter of the period known is a burst (a forced update), not a period; the
    period is the upper median of the last `PERIOD_SAMPLES` intervals, so one late message does not move it.
    Built with `tuple.__new__`, not `_replace`: every message goes through here.
    """
    name, topic, last_message, latest, _, period, intervals, lossless = feed
    interval = now - last_message
    if same_components and interval > 0.0 and interval >= period / 4:
        intervals = (*intervals[-(PERIOD_SAMPLES - 1) :], interval)
        period = sorted(intervals)[len(intervals) // 2]
    return _new_tuple(Feed, (name, topic, now, latest, revision, period, intervals, lossless))


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
    hardware_id: str,
    values: tuple[tuple[str, str], ...],
    now: float,
    changes: int,
    feed: str,
) -> Component:
    # The texts come interned from the decoders (robots of one fleet repeat the same messages and keys),
    # so each is stored once across the fleet with no work here.
    return _new_tuple(Component, (key, level, message, hardware_id, values, now, changes, feed))


def _merged(
    previous: Component,
    level: Level,
    message: str,
    hardware_id: str,
    values: tuple[tuple[str, str], ...],
    now: float,
    feed: str,
) -> Component:
    """The component's record after a status: `previous` itself when the status says nothing new.

    An empty hardware_id (diagnostic_updater's start-up status) keeps the one the component has.
    """
    hardware_id = hardware_id or previous.hardware_id
    if (
        previous.level is level
        and previous.message == message
        and previous.values == values
        and previous.hardware_id == hardware_id
        and previous.feed == feed
    ):
        return previous
    changes = previous.level_changes + (previous.level is not level)
    return _component(previous.key, level, message, hardware_id, values, now, changes, feed)


def _replace_components(
    state: RobotState, components: dict[ComponentKey, Component], now: float
) -> RobotState:
    """`state` with only `components`: feeds forget the others, and feeds that carry none go.

    Expectations the components no longer meet get their stand-ins.
    """
    dropped = sum([c.level_changes for key, c in state.components.items() if key not in components])
    components = expected_components(state.listing, components, now)
    carried = {component.feed for component in components.values()}
    feeds = tuple(
        feed.with_latest(tuple(key if key in components else None for key in feed.latest), feed.revision + 1)
        for feed in state.feeds
        if feed.name in carried
    )
    return state._replace(
        components=MappingProxyType(components),
        revision=state.revision + 1,
        feeds=feeds,
        missing=state.missing.intersection(components),
        dropped_level_changes=state.dropped_level_changes + dropped,
    )
