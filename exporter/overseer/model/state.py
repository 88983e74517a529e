"""What the model holds: a robot's state, the feeds it is heard on, its components' last statuses, the limits.

Robot states are immutable and replaced whole on every message, so a snapshot of the fleet is a shallow
copy of them. Times the model judges by (last message, last update, discovery, departure) are monotonic
seconds: a step of the wall clock changes no level. Each robot keeps the offset between the wall clock and
the monotonic one at its last message, so the times reported to users are wall-clock times.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from types import MappingProxyType
from typing import Literal, NamedTuple

from overseer.levels import Level

# (name, discriminator): the discriminator is '' for every component but the statuses of one name that a
# robot reports side by side with different hardware_ids in one array (a genuine clash): those are kept
# apart, each under its hardware_id.
ComponentKey = tuple[str, str]

UNREPORTED = "expected, not reported"  # what the stand-in of an expected component no one reported says
STALE_PERIODS = 3.0  # a component is STALE after this many of its producer's periods without an update
PERIOD_SAMPLES = 5  # intervals a feed's period is the median of
_OFFSET_JITTER = 0.001  # seconds: a change of the clocks' offset smaller than this is how they were read


@dataclass(frozen=True)
class StaleOverride:
    """Components whose whole name matches `pattern` are STALE after exactly `stale_after` seconds."""

    pattern: re.Pattern[str]
    stale_after: float


@dataclass(frozen=True)
class FleetLimits:
    """Time limits and caps that bound what the model keeps."""

    stale_after: float = 5.0
    robot_timeout: float = 10.0
    expire_after: float = 7 * 86400.0  # a week: a robot dead on Friday evening is still down on Monday
    max_robots: int = 10_000
    max_components_per_robot: int = 1_000
    max_values_per_component: int = 64
    max_string_length: int = 1_024
    max_feeds_per_robot: int = 64
    stale_periods: float = STALE_PERIODS
    stale_overrides: tuple[StaleOverride, ...] = ()


class Component(NamedTuple):
    """The last status a component reported; `level` is the reported level, before staleness.

    `last_update` (monotonic) is when it was last reported in a message other than its feed's latest one;
    while it is in that latest message, the feed's last message time applies instead
    (`FleetSnapshot.last_update`). This lets an unchanged message refresh all it carries by replacing one
    `Feed`. `hardware_id` is the latest non-empty hardware_id reported (diagnostic_updater's start-up
    status has none). A named tuple, not a frozen dataclass: it is built for every status that changed,
    and a frozen dataclass is four times slower to build. `key` is the very tuple that keys it in its
    robot's components (and in its feed's `latest`).
    """

    key: ComponentKey
    level: Level
    message: str
    hardware_id: str
    values: tuple[tuple[str, str], ...]
    last_update: float
    level_changes: int
    feed: str  # the feed that reported it last

    @property
    def name(self) -> str:
        """The status's name."""
        return self.key[0]


@dataclass(frozen=True, slots=True)
class Expectation:
    """Components a robot's inventory entry says it must report: one by name, or `at_least` matching."""

    shown_as: str  # the component that stands for it while unmet: the name, 'prefix*' or the regex
    exact: str = ""
    prefix: str = ""
    pattern: re.Pattern[str] | None = None
    at_least: int = 1

    def matches(self, name: str) -> bool:
        """True when a component called `name` counts towards this expectation."""
        if self.pattern is not None:
            return self.pattern.fullmatch(name) is not None
        if self.prefix:
            return name.startswith(self.prefix)
        return name == self.exact

    def unmet_message(self, reported: int) -> str:
        """What the component standing for this expectation says, with `reported` matching components."""
        if self.exact:
            return UNREPORTED
        what = f"matching {self.prefix}*" if self.prefix else f"matching {self.shown_as}"
        counts = f"{reported or 'none'} reported, {self.at_least - reported} missing"
        return f"expected at least {self.at_least} components {what}: {counts}"


@dataclass(frozen=True, slots=True)
class ListedRobot:
    """A robot of the inventory: its labels (sorted by name) and the components it must report."""

    labels: tuple[tuple[str, str], ...] = ()
    expected: tuple[Expectation, ...] = ()

    def expects(self, name: str) -> bool:
        """True when a component called `name` is one this robot must report."""
        return any(expectation.matches(name) for expectation in self.expected)


class Feed(NamedTuple):
    """One stream a robot is heard on: a topic, from one publisher where the transport tells them apart.

    `latest` holds, in the message's order, the component each status of the feed's latest message went
    to, or None where the status lost something (dropped, cut short, a repeated name) or another feed
    took the component over: an ingest may then apply only the statuses that changed, and only while
    `lossless` (no None in `latest`, kept beside it so that no message looks for one). `revision` counts
    the changes an ingest's memory of the feed depends on. `period` is the median of the last intervals
    between messages that carried the same components (0.0 until one is known): start-up arrays and
    other partial ones do not count.
    """

    name: str
    topic: str
    last_message: float
    latest: tuple[ComponentKey | None, ...]
    revision: int = 0
    period: float = 0.0
    intervals: tuple[float, ...] = ()
    lossless: bool = True

    def with_latest(self, latest: tuple[ComponentKey | None, ...], revision: int) -> Feed:
        """The feed with another latest message's components, at `revision`."""
        return self._replace(latest=latest, revision=revision, lossless=None not in latest)


ForgetReason = Literal["expired", "retired", "unlisted", "reattributed"]


class Forgetting(NamedTuple):
    """Why a robot was forgotten, and when (unix time)."""

    reason: ForgetReason
    at: float


# A component as remembered: its name, hardware_id, reported level and message (not its key-values).
RememberedComponent = tuple[str, str, int, str]


class RememberedRobot(NamedTuple):
    """A robot heard before this start: its name, its transport, when it was last heard (unix time).

    `down` when it was down then (silent, or its publisher gone): it is down until it speaks again.
    `components` are its components then, as a clean stop keeps them (none after a crash).
    """

    name: str
    transport: str
    heard_at: float
    down: bool = False
    components: tuple[RememberedComponent, ...] = ()


class RobotState(NamedTuple):
    """One robot as last seen; replaced whole, never mutated.

    `missing` holds the components that are not in their feed's latest message (their own `last_update`
    applies); it is empty for almost every robot, so it is shared. `left_at` is when a transport that
    tracks publishers (DDS discovery, Zenoh liveliness, the ROS graph) saw the robot's last diagnostics
    publisher go: the robot is down from then until a message arrives after it. `revision` changes with
    anything a judgement or a rendering of the robot depends on but the feeds' times. `listing` is its
    entry in the inventory (labels, expected components), None for a robot known only by discovery.
    A named tuple, not a frozen dataclass: every message replaces one, and a frozen dataclass took five
    times as long to build.
    """

    name: str
    transport: str
    last_message: float | None
    components: MappingProxyType[ComponentKey, Component]
    discovered_at: float
    revision: int = 0
    feeds: tuple[Feed, ...] = ()
    missing: frozenset[ComponentKey] = frozenset()
    left_at: float | None = None
    wall_offset: float = 0.0  # wall clock minus monotonic clock, at the last message (or discovery)
    up_since: float = 0.0  # the first message since it was last down (silent, or its publisher gone)
    listing: ListedRobot | None = None
    dropped_level_changes: int = 0  # those of components it no longer has, so that its total never falls

    @property
    def level_changes(self) -> int:
        """Every level change its components reported while it was followed, those dropped since included."""
        return self.dropped_level_changes + sum(
            [component.level_changes for component in self.components.values()]
        )

    @property
    def last_seen(self) -> float:
        """When the robot last sent a message, or when it was discovered if it never did (monotonic)."""
        return self.discovered_at if self.last_message is None else self.last_message

    @property
    def publisher_alive(self) -> bool:
        """False from the departure of its last publisher until a message arrives after it."""
        return self.left_at is None or (self.last_message is not None and self.last_message > self.left_at)

    def wall_time(self, monotonic: float) -> float:
        """A monotonic time of this robot as the wall clock read it then (unix time)."""
        return monotonic + self.wall_offset

    @property
    def last_message_wall(self) -> float | None:
        """The unix time of the last message, or None."""
        return None if self.last_message is None else self.last_message + self.wall_offset

    def feed(self, name: str) -> Feed | None:
        """The feed called `name`, or None."""
        for feed in self.feeds:
            if feed.name == name:
                return feed
        return None


def steady_wall_offset(previous: float, now: float, wall: float) -> float:
    """Wall clock minus monotonic clock read as `now` and `wall`, or `previous` within a millisecond of it.

    The two clocks are read one after the other, a few hundred nanoseconds (or a preemption) apart: an
    offset that moved by that much would date one message's events differently (a robot's `robot_up`
    before the `appeared` of the very message that brought it up). A step of the wall clock still counts.
    """
    offset = wall - now
    return previous if -_OFFSET_JITTER < offset - previous < _OFFSET_JITTER else offset


def up_since(limits: FleetLimits, state: RobotState, now: float) -> float:
    """When the run of messages a message at `now` belongs to began: now, after a silence or a departure."""
    last = state.last_message
    if last is None or not state.publisher_alive:
        return now
    if now - last <= limits.robot_timeout:  # within the shortest timeout a robot may have: no gap
        return state.up_since
    return now if now - last > robot_timeout(limits, state) else state.up_since


def learned_period(robot: RobotState) -> float | None:
    """The robot's own period as learned: its fastest feed's (None while no feed's is known)."""
    periods = [feed.period for feed in robot.feeds if feed.period > 0.0]
    return min(periods) if periods else None


def robot_period(limits: FleetLimits, robot: RobotState) -> float:
    """The robot's own period: its fastest feed's, or `stale_after` while none is known."""
    period = learned_period(robot)
    return limits.stale_after if period is None else period


def feed_stale_after(limits: FleetLimits, feed: Feed | None) -> float:
    """How long the components of `feed` stay fresh: `stale_after`, or a few periods of a slower feed.

    A feed's period not known yet (one message, or only partial ones) counts as `stale_after`, so a
    producer slower than `stale_after` is not taken for stale before its second message.
    """
    period = feed.period if feed is not None and feed.period > 0.0 else limits.stale_after
    return _rounded(max(limits.stale_after, limits.stale_periods * period))


def robot_timeout(limits: FleetLimits, robot: RobotState) -> float:
    """How long the robot may be silent before it is down: `robot_timeout`, or longer for a slow robot."""
    return _rounded(max(limits.robot_timeout, limits.stale_periods * robot_period(limits, robot)))


def _rounded(seconds: float) -> float:
    """Up to a tenth of a second, so that a period's jitter does not change a judgement's bound."""
    return -(-round(seconds * 10, 6) // 1) / 10
