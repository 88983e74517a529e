"""The fleet's series rendered as exposition lines, fast enough for 100,000 series per scrape.

Each robot's lines are kept between scrapes and rebuilt only when the robot's state or the set of its
stale components changed (most robots merely republished the same diagnostics); within a changed robot
only the components whose stamps (hashes of what their lines are rendered from) or judged levels
changed are rendered again. They are kept deflated (`deflated`), so
that a gzip scrape sends the unchanged robots' bytes as they are, and runs of robots that held still for
a render as one piece compressed again (`joined_runs`). The lines are the same bytes in every
format a scrape may ask for (`exposition_formats`), so one cached part serves the text format and
OpenMetrics alike; `assembler` adds the headers. The tests hold the result byte-identical to
prometheus-client's rendering of the same fleet.
"""

from __future__ import annotations

import re
import threading
from array import array
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from itertools import compress
from math import copysign
from operator import ne
from typing import cast

from prometheus_client.utils import floatToGoString

from overseer.config.metrics import NO_VALUE_KEYS
from overseer.fleet.deflated import Deflated, deflate, inflate
from overseer.fleet.joined_runs import JoinedRuns
from overseer.fleet.message_labels import DEFAULT_MESSAGE_LABELS, MessageLabels, message_label_value
from overseer.fleet.metric_values import NumericValues
from overseer.fleet.stamps import field_hashes
from overseer.levels import Level, worst
from overseer.model import Component, FleetModel, FleetSnapshot, RobotState
from overseer.model.snapshot import RobotTiming
from overseer.model.state import ComponentKey, learned_period

# prometheus-client's number format (Go's), so values render exactly as its families' do.
go_float = cast(Callable[[float], str], floatToGoString)


def escape_label_value(value: str) -> str:
    """A label value as the exposition formats write it between double quotes."""
    return value.replace("\\", r"\\").replace("\n", r"\n").replace('"', r"\"")


@dataclass(frozen=True, slots=True)
class _RobotLines:
    """One robot's rendered per-component lines and what they were rendered for.

    `levels`, `changes`, `values` and `messages` hold every component's lines of each family, deflated
    (`deflated`: a tenth of the memory, and a scrape sends them as they are); component i's lines of
    family k start at `offsets[(count + 1) * k + i]` of the family's text, where `count` components
    were rendered (`offsets[(count + 1) * k + count]` is the family's length). `stamps` say what they
    were rendered from, two a component (`_stamps`), and `component_levels` their levels as rendered:
    a component with the same stamps renders the same lines (when the robot's up, timing and staleness
    did not change), so they are copied instead, and one whose values alone changed renders its values
    again (none when no value is exported: `_lines_to_render`). The records themselves are not kept: a
    fleet scraped a minute apart replaces nearly half of them meanwhile, and the cache would keep each
    old one alive (about 400 bytes) beside the new.
    """

    signature: tuple[tuple[int, float], bool, tuple[int, ...]]
    timing: RobotTiming  # when its components turn STALE, for this revision
    robot_level: Level
    info: str  # its ros_diagnostics_robot_info line
    counts: bytes  # its ros_diagnostics_robot_components lines
    robot_changes: bytes  # its ros_diagnostics_robot_level_changes_total line
    levels: Deflated
    changes: Deflated
    values: Deflated
    messages: Deflated
    stamps: array[int]
    component_levels: bytes
    offsets: array[int]

    def family(self, family: int) -> Deflated:
        """The lines of family `family` (0 levels, 1 level changes, 2 values, 3 status messages)."""
        return (self.levels, self.changes, self.values, self.messages)[family]


class FleetExposition:
    """Renders a fleet model's series (a worker's robots, or the whole fleet) as one `ExpositionPart`."""

    def __init__(
        self,
        model: FleetModel,
        value_keys: re.Pattern[str],
        *,
        messages: MessageLabels = DEFAULT_MESSAGE_LABELS,
        level_changes: bool = True,
    ) -> None:
        """Render `model`, exporting key-values whose key fully matches `value_keys`.

        `messages` chooses the components with a status-message series and the length of its label;
        `level_changes` False leaves out `ros_diagnostics_level_changes_total` (a series per component).
        """
        self._model = model
        self._value_keys = value_keys
        self._exports_values = value_keys.pattern != NO_VALUE_KEYS
        self._messages = messages
        self._level_changes = level_changes
        self._robots: dict[str, _RobotLines] = {}
        # Each per-component family's robots, in runs recompressed as one piece once they hold still.
        self._runs = tuple(JoinedRuns() for _ in range(FAMILIES))
        self._lock = threading.Lock()

    def render_part(self) -> ExpositionPart:
        """The model's series and counters now, for an assembler to write out (with other workers')."""
        with self._lock:
            return self._render(self._model.snapshot())

    def _render(self, snapshot: FleetSnapshot) -> ExpositionPart:
        render = _RenderCache(
            NumericValues(self._value_keys),
            self._exports_values,
            self._messages,
            self._level_changes,
        )
        previous, current = self._robots, {}
        levels, changes, values, messages = [], [], [], []
        robot_level, robot_up, last_message, periods, info = [], [], [], [], []
        counts, robot_changes = [], []
        names = [robot.name for robot in snapshot.robots]
        for robot in snapshot.robots:
            label = f'{{robot="{escape_label_value(robot.name)}"}} '
            up = snapshot.robot_up(robot)
            # Popped, so that a robot's old lines go as soon as its new ones exist: the old and the
            # new cache of the whole fleet never need memory at the same time.
            lines = _lines_for(snapshot, robot, up, previous.pop(robot.name, None), render)
            current[robot.name] = lines
            levels.append(lines.levels)
            changes.append(lines.changes)
            values.append(lines.values)
            messages.append(lines.messages)
            robot_level.append(f"ros_diagnostics_robot_level{label}{_LEVEL_VALUES[lines.robot_level]}\n")
            robot_up.append(f"ros_diagnostics_robot_up{label}{'1.0' if up else '0.0'}\n")
            info.append(lines.info)
            counts.append(lines.counts)
            robot_changes.append(lines.robot_changes)
            if robot.last_message is not None:
                last_message.append(
                    f"ros_diagnostics_robot_last_message_timestamp_seconds{label}"
                    f"{go_float(robot.last_message + robot.wall_offset)}\n"
                )
            period = learned_period(robot)
            if period is not None:
                period_text = render.number(round(period, 3))
                periods.append(f"ros_diagnostics_robot_period_seconds{label}{period_text}\n")
        self._robots = current
        levels_runs, changes_runs, values_runs, messages_runs = self._runs
        return ExpositionPart(
            len(current),
            (
                levels_runs.join(names, levels),
                deflate("".join(robot_level).encode()),
                deflate("".join(robot_up).encode()),
                deflate("".join(last_message).encode()),
                deflate("".join(periods).encode()),
                deflate("".join(info).encode()),
                deflate(b"".join(counts)),
                deflate(b"".join(robot_changes)),
                changes_runs.join(names, changes),
                values_runs.join(names, values),
                messages_runs.join(names, messages),
            ),
            dict(snapshot.message_counts),
            dict(snapshot.dropped_statuses),
            snapshot.truncated_strings,
            dict(snapshot.source_errors),
            dict(snapshot.forgotten_counts),
        )


@dataclass(frozen=True, slots=True)
class ExpositionPart:
    """The rendered series of one model (a worker's robots): lines per fleet family, and its counters."""

    robots: int
    families: tuple[Deflated, ...]  # the lines of each of metric_families.FLEET_FAMILIES, no header
    message_counts: dict[tuple[str, str], int]
    dropped_statuses: dict[str, int]
    truncated_strings: int
    source_errors: dict[tuple[str, str], int]
    forgotten: dict[str, int]  # robots forgotten, by reason


def _lines_for(
    snapshot: FleetSnapshot, robot: RobotState, up: bool, cached: _RobotLines | None, render: _RenderCache
) -> _RobotLines:
    # A robot forgotten and followed again starts its revisions over: when it was discovered tells them apart.
    revision = (robot.revision, robot.discovered_at)
    same_revision = cached is not None and cached.signature[0] == revision
    timing = cached.timing if cached is not None and same_revision else snapshot.timing(robot)
    # How far its components have gone STALE: while that holds, so do their levels.
    signature = (revision, up, snapshot.staleness(robot, timing))
    if cached is not None and cached.signature == signature:
        return cached
    # Only the bytes are kept between scrapes (memory is the limit at 100,000 components); the
    # per-render caches make rendering cheap, since a fleet repeats its names, keys and values.
    # Lines copied from the cache must have been rendered with the same up, staleness and timing.
    copyable = (
        cached
        if cached is not None and cached.signature[1:] == signature[1:] and cached.timing == timing
        else None
    )
    missing = robot.missing
    levels = snapshot.component_levels(robot, up)
    judged = bytes(levels)
    stamps = _stamps(robot.components, missing)
    robot_label = f'robot="{render.escape(robot.name)}"'
    info = _info_line(robot, render.escape) if cached is None or not same_revision else cached.info
    robot_changes = _ROBOT_CHANGES.format(robot_label, render.number(robot.level_changes)).encode()
    to_render = (
        _lines_to_render(copyable.stamps, copyable.component_levels, stamps, judged, render.exports_values)
        if copyable is not None
        else (list(range(len(judged))),) * FAMILIES
    )
    if copyable is not None and not any(to_render) and len(stamps) == len(copyable.stamps):
        # Nothing to render in any family (most often values changed that are not exported,
        # `metrics.value_keys: []`): the robot's lines are the cached ones.
        return _RobotLines(
            signature,
            timing,
            copyable.robot_level,
            info,
            copyable.counts,
            robot_changes,
            copyable.levels,
            copyable.changes,
            copyable.values,
            copyable.messages,
            stamps,
            judged,
            copyable.offsets,
        )
    items = list(robot.components.items())
    lines = _ComponentLines(items, levels, robot_label, render)
    offsets: array[int] = array("I")
    levels_lines, changes, values, messages = (
        _family_lines(cached, family, indices, len(items), render_line, offsets)
        for family, (indices, render_line) in enumerate(
            zip(to_render, (lines.level, lines.changes, lines.values, lines.message), strict=True)
        )
    )
    return _RobotLines(
        signature,
        timing,
        worst(levels) if up else Level.STALE,
        info,
        _counts_lines(robot_label, levels, render.number),
        robot_changes,
        levels_lines,
        changes,
        values,
        messages,
        stamps,
        judged,
        offsets,
    )


FAMILIES = 4  # per-component families: levels, level changes, values, status messages


# What a component's lines are rendered from but its values (and its level as judged, kept beside).
_RENDERED_FROM = bytes(
    Component._fields.index(field) for field in ("key", "level", "message", "hardware_id", "level_changes")
)
_VALUES = bytes([Component._fields.index("values")])
_MISSING = -1  # the first stamp of a component missing from its feed's latest message: hash() is never -1


def _stamps(components: Mapping[ComponentKey, Component], missing: frozenset[ComponentKey]) -> array[int]:
    """Two hashes a component, of what its lines are rendered from: all but its values, and its values.

    The first hash of each of the n components, then the second of each. A component missing from its
    feed's latest message renders by its own time, so it is never copied: its first stamp is -1, which
    no hash is. Two records whose stamps agree render the same lines but for a hash collision (one in
    2**64 a change on a 64-bit build, and then its lines are a change late). Hashed in C where it was
    built (`stamps`): a changed robot's components are stamped at every scrape.
    """
    records = tuple(components.values())
    stamps: array[int] = array("q")
    stamps.frombytes(field_hashes(records, _RENDERED_FROM))
    if missing:
        for index, key in enumerate(components):
            if key in missing:
                stamps[index] = _MISSING
    stamps.frombytes(field_hashes(records, _VALUES))
    return stamps


def _lines_to_render(
    reusable: array[int], reusable_levels: bytes, stamps: array[int], levels: bytes, values: bool
) -> tuple[list[int], list[int], list[int], list[int]]:
    """The components to render again in each family, in order; the lines of the others can be copied.

    `reusable` are the stamps of the records the cached lines were rendered from (`_stamps`), at the
    same indices, and `reusable_levels` their levels then (`levels` are those now). A component whose
    values alone changed renders its values again, and the levels, level changes and status messages
    are copied, compressed, as they were: in a fleet most changes are values (a voltage, a temperature).
    Any other change (a message, a level, a hardware_id) renders all four of the component's families:
    a third stamp to tell a message apart would cost every component 8 bytes more. With `values` False
    (no value exported) a changed value renders nothing.
    """
    old_count, new_count = len(reusable) // 2, len(stamps) // 2
    count = min(old_count, new_count)
    indices = range(count)
    # Whole runs of stamps compared at once: most of a changed robot is unchanged.
    firsts, old_firsts = stamps[:count], reusable[:count]
    if firsts == old_firsts and _MISSING not in firsts:
        every: list[int] = []
    else:
        every = [i for i in indices if firsts[i] != old_firsts[i] or firsts[i] == _MISSING]
    seconds, old_seconds = stamps[new_count : new_count + count], reusable[old_count : old_count + count]
    # With no value exported every value line is empty: a changed value has none to render.
    same_values = not values or seconds == old_seconds
    revalued = [] if same_values else list(compress(indices, map(ne, seconds, old_seconds)))
    # The level decides whether a message has a line (MessageLabels "problems"), and is its label.
    judged, old_judged = levels[:count], reusable_levels[:count]
    moved = [] if judged == old_judged else list(compress(indices, map(ne, judged, old_judged)))
    added = range(count, new_count)
    level_lines = sorted({*every, *moved}) if every and moved else every or moved
    value_lines = sorted({*every, *revalued}) if every and revalued else every or revalued
    return (
        [*level_lines, *added],
        [*every, *added],
        [*value_lines, *added],
        [*level_lines, *added],
    )


def _family_lines(
    cached: _RobotLines | None,
    family: int,
    to_render: list[int],
    count: int,
    render_line: Callable[[int], bytes],
    offsets: array[int],
) -> Deflated:
    """A family's lines of `count` components: `to_render` rendered, the others copied from `cached`.

    Where each component's lines start (and where the last ends) is appended to `offsets`. A family
    none of whose lines changed, or whose lines come out the same bytes, is the cached piece itself.
    """
    if cached is not None:
        cached_count = len(cached.stamps) // 2
        cached_piece = cached.family(family)
        old = cached.offsets
        base = (cached_count + 1) * family
        if not to_render and count == cached_count:
            offsets.extend(old[base : base + count + 1])
            return cached_piece
    starts: array[int] = array("I")
    pieces: list[bytes] = []
    size = following = 0
    cached_text = b""

    def copy_cached(stop: int) -> None:
        """Copy the cached lines of components `following` to `stop` (which kept their index)."""
        nonlocal size, cached_text
        if not cached_text:
            cached_text = inflate(cached_piece)
        start, end = old[base + following], old[base + stop]
        pieces.append(cached_text[start:end])
        shift = size - start
        if shift:
            starts.extend([offset + shift for offset in old[base + following : base + stop]])
        else:
            starts.extend(old[base + following : base + stop])
        size += end - start

    for index in to_render:
        if index != following:
            copy_cached(index)
        line = render_line(index)
        starts.append(size)
        if line:
            pieces.append(line)
            size += len(line)
        following = index + 1
    if following != count:
        copy_cached(count)
    starts.append(size)
    offsets.extend(starts)
    text = b"".join(pieces)
    # A changed status mostly changes its values alone: when its family still comes out the same
    # bytes (a value not exported changed), the cached piece is kept (cheaper to compare than compress).
    if (
        cached is not None
        and cached_piece.size == len(text)
        and (cached_text or inflate(cached_piece)) == text
    ):
        return cached_piece
    return deflate(text)


class _ComponentLines:
    """A robot's components' lines, each family's rendered on demand, for `_family_lines`."""

    def __init__(
        self,
        items: list[tuple[ComponentKey, Component]],
        levels: list[Level],
        robot_label: str,
        render: _RenderCache,
    ) -> None:
        """Render `items` (the robot's components), now at `levels`, of the robot labelled `robot_label`."""
        self._items = items
        self._levels = levels
        self.robot_label = robot_label
        self._render = render
        self._identities: dict[int, str] = {}

    def _identity(self, index: int) -> str:
        """The component's labels but the robot's."""
        identity = self._identities.get(index)
        if identity is None:
            component = self._items[index][1]
            escape = self._render.escape
            identity = f'component="{escape(component.name)}",hardware_id="{escape(component.hardware_id)}"'
            self._identities[index] = identity
        return identity

    def level(self, index: int) -> bytes:
        """Its ros_diagnostics_level line."""
        labels = f"{self._identity(index)},{self.robot_label}"
        return f"ros_diagnostics_level{{{labels}}} {_LEVEL_VALUES[self._levels[index]]}\n".encode()

    def changes(self, index: int) -> bytes:
        """Its ros_diagnostics_level_changes_total line (none when that family is not exported)."""
        if not self._render.level_changes:
            return b""
        labels = f"{self._identity(index)},{self.robot_label}"
        number = self._render.number(float(self._items[index][1].level_changes))
        return f"ros_diagnostics_level_changes_total{{{labels}}} {number}\n".encode()

    def values(self, index: int) -> bytes:
        """Its ros_diagnostics_value lines, one per exported numeric value."""
        render = self._render
        if not render.exports_values:
            return b""
        component = self._items[index][1]
        pairs = list(render.numbers.pairs(component.values))
        if not pairs:  # most components: no value exported
            return b""
        identity, robot_label, escape, number = (
            self._identity(index),
            self.robot_label,
            render.escape,
            render.number,
        )
        return "".join(
            [
                f'ros_diagnostics_value{{{identity},key="{escape(key)}",{robot_label}}} {number(value)}\n'
                for key, value in pairs
            ]
        ).encode()

    def message(self, index: int) -> bytes:
        """Its ros_diagnostics_status_message line, or none (MessageLabels)."""
        message = self._render.message(self._items[index][1])
        if message is None:
            return b""
        return _status_message_line(self._identity(index), self._levels[index], message, self.robot_label)


_LEVEL_VALUES = {level: go_float(float(level)) for level in Level}
_ZERO, _NEGATIVE_ZERO = go_float(0.0), go_float(-0.0)


def _info_line(robot: RobotState, escape: Callable[[str], str]) -> str:
    """The robot's ros_diagnostics_robot_info line: its name and inventory labels, by label name."""
    labels = [("robot", robot.name)]
    if robot.listing is not None:
        labels.extend(robot.listing.labels)
    text = ",".join(f'{name}="{escape(value)}"' for name, value in sorted(labels))
    return f"ros_diagnostics_robot_info{{{text}}} 1.0\n"


def _counts_lines(robot_label: str, levels: list[Level], number: Callable[[float], str]) -> bytes:
    """The robot's ros_diagnostics_robot_components lines: its components at each level, 0 included."""
    count = levels.count
    return (
        f'ros_diagnostics_robot_components{{level="OK",{robot_label}}} {number(count(_OK))}\n'
        f'ros_diagnostics_robot_components{{level="WARN",{robot_label}}} {number(count(_WARN))}\n'
        f'ros_diagnostics_robot_components{{level="ERROR",{robot_label}}} {number(count(_ERROR))}\n'
        f'ros_diagnostics_robot_components{{level="STALE",{robot_label}}} {number(count(_STALE))}\n'
    ).encode()


_OK, _WARN, _ERROR, _STALE = Level
_ROBOT_CHANGES = "ros_diagnostics_robot_level_changes_total{{{}}} {}\n"


def _status_message_line(identity: str, level: Level, message: str, robot_label: str) -> bytes:
    """A component's ros_diagnostics_status_message line: its level now, and its escaped message label."""
    return (
        f'ros_diagnostics_status_message{{{identity},level="{level.name}",'
        f'message="{message}",{robot_label}}} 1.0\n'
    ).encode()


class _RenderCache:
    """Memoized escaping and number formatting for one render."""

    def __init__(
        self, numbers: NumericValues, exports_values: bool, messages: MessageLabels, level_changes: bool
    ) -> None:
        self.numbers = numbers
        self.exports_values = exports_values  # False: no key is exported (`NO_VALUE_KEYS`)
        self.level_changes = level_changes
        self._message_length = messages.length
        # MessageLabels.wants, inlined (it runs for every component rendered); the tests hold them equal.
        self._all_messages, self._problem_messages = messages.mode == "all", messages.mode == "problems"
        self._message_labels: dict[str, str] = {}
        self._escaped: dict[str, str] = {}
        self._formatted: dict[float, str] = {}

    def escape(self, text: str) -> str:
        escaped = self._escaped.get(text)
        if escaped is None:
            escaped = self._escaped[text] = escape_label_value(text)
        return escaped

    def message(self, component: Component) -> str | None:
        """The escaped message label of `component`'s status-message line, or None for no line."""
        if not (self._all_messages or (self._problem_messages and component.level)):
            return None
        text = component.message
        label = self._message_labels.get(text)
        if label is None:
            label = escape_label_value(message_label_value(text, self._message_length))
            self._message_labels[text] = label
        return label

    def number(self, value: float) -> str:
        if not value:  # 0.0 == -0.0 as keys, but they render differently (most counts are 0)
            return _NEGATIVE_ZERO if copysign(1.0, value) < 0 else _ZERO
        formatted = self._formatted.get(value)
        if formatted is None:
            formatted = self._formatted[value] = go_float(value)
        return formatted
