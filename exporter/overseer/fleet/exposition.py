"""The fleet's series rendered as exposition lines, fast enough for 100,000 series per scrape.

Each robot's lines are kept between scrapes and rebuilt only when the robot's state or the set of its
stale components changed (most robots merely republished the same diagnostics); within a changed robot
only the components whose record changed are rendered again. They are kept deflated (`deflated`), so
that a gzip scrape sends the unchanged robots' bytes as they are. The lines are the same bytes in every
format a scrape may ask for (`exposition_formats`), so one cached part serves the text format and
OpenMetrics alike; `assembler` adds the headers. The tests hold the result byte-identical to
prometheus-client's rendering of the same fleet.
"""

from __future__ import annotations

import re
import threading
from array import array
from collections.abc import Callable
from dataclasses import dataclass
from typing import cast

from prometheus_client.utils import floatToGoString

from overseer.fleet.deflated import Deflated, deflate, inflate, join
from overseer.fleet.message_labels import DEFAULT_MESSAGE_LABELS, MessageLabels, message_label_value
from overseer.fleet.metric_values import NumericValues
from overseer.levels import Level, worst
from overseer.model import Component, FleetModel, FleetSnapshot, RobotState
from overseer.model.snapshot import RobotTiming
from overseer.model.state import learned_period

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
    family k start at `offsets[FAMILIES * i + k]` of the family's text. `components` are the records
    they were rendered from (None for those missing from their feed's latest message): a component whose
    record is the same object again renders the same lines (when the robot's up, timing and staleness did
    not change), so they are copied instead.
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
    components: tuple[Component | None, ...]
    offsets: array[int]


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
        self._messages = messages
        self._level_changes = level_changes
        self._robots: dict[str, _RobotLines] = {}
        self._lock = threading.Lock()

    def render_part(self) -> ExpositionPart:
        """The model's series and counters now, for an assembler to write out (with other workers')."""
        with self._lock:
            return self._render(self._model.snapshot())

    def _render(self, snapshot: FleetSnapshot) -> ExpositionPart:
        render = _RenderCache(NumericValues(self._value_keys), self._messages, self._level_changes)
        previous, current = self._robots, {}
        levels, changes, values, messages = [], [], [], []
        robot_level, robot_up, last_message, periods, info = [], [], [], [], []
        counts, robot_changes = [], []
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
            robot_level.append(f"ros_diagnostics_robot_level{label}{go_float(float(lines.robot_level))}\n")
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
                periods.append(f"ros_diagnostics_robot_period_seconds{label}{go_float(round(period, 3))}\n")
        self._robots = current
        return ExpositionPart(
            len(current),
            (
                join(levels),
                deflate("".join(robot_level).encode()),
                deflate("".join(robot_up).encode()),
                deflate("".join(last_message).encode()),
                deflate("".join(periods).encode()),
                deflate("".join(info).encode()),
                deflate(b"".join(counts)),
                deflate(b"".join(robot_changes)),
                join(changes),
                join(values),
                join(messages),
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
    escape, number, pairs, message_label = render.escape, render.number, render.numbers.pairs, render.message
    with_changes = render.level_changes
    robot_label = f'robot="{escape(robot.name)}"'
    reusable = (
        cached.components
        if cached is not None and cached.signature[1:] == signature[1:] and cached.timing == timing
        else ()
    )
    lines = _LinesBuilder(cached)
    missing = robot.missing
    levels = snapshot.component_levels(robot, up)
    items = list(robot.components.items())
    # A component whose record is the same object at the same place, while neither up nor freshness
    # changed, renders the same lines: only the others are rendered, the rest is copied.
    to_render = [
        index
        for index, (old, (key, component)) in enumerate(zip(reusable, items, strict=False))
        if old is not component or key in missing
    ]
    to_render.extend(range(len(reusable), len(items)))
    for index in to_render:
        component = items[index][1]
        identity = f'component="{escape(component.name)}",hardware_id="{escape(component.hardware_id)}"'
        labels = f"{{{identity},{robot_label}}} "
        values = "".join(
            [
                f'ros_diagnostics_value{{{identity},key="{escape(key)}",{robot_label}}} {number(value)}\n'
                for key, value in pairs(component.values)
            ]
        )
        level = levels[index]
        message = message_label(component)
        lines.add(
            index,
            f"ros_diagnostics_level{labels}{_LEVEL_VALUES[level]}\n".encode(),
            f"ros_diagnostics_level_changes_total{labels}{number(float(component.level_changes))}\n".encode()
            if with_changes
            else b"",
            values.encode(),
            b"" if message is None else _status_message_line(identity, level, message, robot_label),
        )
    level_lines, changes, values_lines, message_lines, offsets = lines.finish(len(levels))
    # A component missing from its feed's latest message renders by its own time: never copied (None).
    records = (
        tuple(component if key not in missing else None for key, component in items)
        if missing
        else tuple(robot.components.values())
    )
    return _RobotLines(
        signature,
        timing,
        worst(levels) if up else Level.STALE,
        _info_line(robot, escape) if cached is None or not same_revision else cached.info,
        _counts_lines(robot_label, levels, number),
        _ROBOT_CHANGES.format(robot_label, number(robot.level_changes)).encode(),
        level_lines,
        changes,
        values_lines,
        message_lines,
        records,
        offsets,
    )


FAMILIES = 4  # per-component families: levels, level changes, values, status messages


class _LinesBuilder:
    """Builds a robot's per-component families of lines from new lines and, between them, the cached ones."""

    def __init__(self, cached: _RobotLines | None) -> None:
        self._cached = cached
        self._cached_text: list[bytes | None] = [None] * FAMILIES  # its families, inflated when needed
        self._pieces: tuple[list[bytes], ...] = tuple([] for _ in range(FAMILIES))
        self._sizes = [0] * FAMILIES
        self._offsets = array("I", self._sizes)
        self._next = 0  # the first component not yet in the pieces

    def add(self, index: int, levels: bytes, changes: bytes, values: bytes, message: bytes) -> None:
        """Component `index`'s freshly rendered lines, one bytes per family; those before it come cached."""
        if index != self._next:
            self._copy_cached(index)
        # Unrolled: this runs for every component rendered, and most have no values or message line.
        pieces, sizes = self._pieces, self._sizes
        pieces[0].append(levels)
        sizes[0] += len(levels)
        pieces[1].append(changes)
        sizes[1] += len(changes)
        if values:
            pieces[2].append(values)
            sizes[2] += len(values)
        if message:
            pieces[3].append(message)
            sizes[3] += len(message)
        self._offsets.extend(sizes)
        self._next = index + 1

    def finish(self, count: int) -> tuple[Deflated, Deflated, Deflated, Deflated, array[int]]:
        """The families' lines for `count` components, and where every component's lines start."""
        self._copy_cached(count)
        levels, changes, values, messages = (
            self._deflated(family, b"".join(pieces)) for family, pieces in enumerate(self._pieces)
        )
        return levels, changes, values, messages, self._offsets

    def _deflated(self, family: int, text: bytes) -> Deflated:
        """`text` deflated, or the cached piece when that holds the very same text (cheaper to compare)."""
        # A changed status mostly changes its values alone: its level and level-changes lines, and
        # so those families of the robot, come out the same bytes.
        if self._cached is not None:
            cached = self._cached_families()[family]
            if cached.size == len(text) and self._cached_text_of(family) == text:
                return cached
        return deflate(text)

    def _cached_families(self) -> tuple[Deflated, Deflated, Deflated, Deflated]:
        assert self._cached is not None
        cached = self._cached
        return cached.levels, cached.changes, cached.values, cached.messages

    def _cached_text_of(self, family: int) -> bytes:
        """A cached family's text, inflated the first time it is needed."""
        text = self._cached_text[family]
        if text is None:
            text = self._cached_text[family] = inflate(self._cached_families()[family])
        return text

    def _copy_cached(self, stop: int) -> None:
        """Copy the cached lines of components `self._next` to `stop` (where they had the same index)."""
        if stop == self._next or self._cached is None:
            return
        cached, first, last = self._cached, FAMILIES * self._next, FAMILIES * stop
        old = cached.offsets
        shifts = []
        for family in range(FAMILIES):
            text = self._cached_text_of(family)
            start, end = old[first + family], old[last + family]
            self._pieces[family].append(text[start:end])
            shifts.append(self._sizes[family] - start)
            self._sizes[family] += end - start
        if any(shifts):
            self._offsets.extend(
                [old[i] + shifts[i % FAMILIES] for i in range(first + FAMILIES, last + FAMILIES)]
            )
        else:
            self._offsets.extend(old[first + FAMILIES : last + FAMILIES])
        self._next = stop


_LEVEL_VALUES = {level: go_float(float(level)) for level in Level}


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

    def __init__(self, numbers: NumericValues, messages: MessageLabels, level_changes: bool) -> None:
        self.numbers = numbers
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
        if not value:  # 0.0 == -0.0 as keys, but they render differently
            return go_float(value)
        formatted = self._formatted.get(value)
        if formatted is None:
            formatted = self._formatted[value] = go_float(value)
        return formatted
