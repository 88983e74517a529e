"""Prometheus text exposition (format 0.0.4) of the fleet, fast enough for 100,000 series per scrape.

It renders exactly the bytes prometheus-client renders from `FleetCollector` (the tests hold the two
equal), but keeps each robot's lines and rebuilds them only when the robot's state or the set of its
stale components changed: between two scrapes most robots merely republished the same diagnostics.
"""

from __future__ import annotations

import bisect
import re
import threading
from array import array
from collections import Counter
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from typing import cast

from prometheus_client.exposition import generate_latest
from prometheus_client.registry import Collector, CollectorRegistry
from prometheus_client.utils import floatToGoString

from overseer import __version__
from overseer.codec import compiled
from overseer.levels import Level, worst
from overseer.model import Component, FleetModel, FleetSnapshot, RobotState
from overseer.serve.message_labels import DEFAULT_MESSAGE_LABELS, MessageLabels, message_label_value
from overseer.serve.metrics import DROP_REASONS, NumericValues, _Families, message_counts

CONTENT_TYPE = "text/plain; version=0.0.4; charset=utf-8"

# prometheus-client's number format (Go's), so values render exactly as the collector's do.
go_float = cast(Callable[[float], str], floatToGoString)


def escape_label_value(value: str) -> str:
    """A label value as the text format writes it between double quotes."""
    return value.replace("\\", r"\\").replace("\n", r"\n").replace('"', r"\"")


@dataclass(frozen=True, slots=True)
class _RobotLines:
    """One robot's rendered per-component lines and what they were rendered for.

    `levels`, `changes`, `values` and `messages` hold every component's lines of each family;
    component i's lines of family k start at `offsets[FAMILIES * i + k]`. `components` are the records
    they were rendered from (None for those missing from the latest message): a component whose record
    is the same object again renders the same lines (when the robot's up and freshness did not change),
    so they are copied instead.
    """

    signature: tuple[int, bool, bool, int]
    revision: int
    other_updates: list[float]  # sorted last updates of components missing from the latest message
    robot_level: Level
    levels: bytes
    changes: bytes
    values: bytes
    messages: bytes
    components: tuple[Component | None, ...]
    offsets: array[int]


class FleetExposition:
    """Renders the fleet model as the metric contract in the Prometheus text format."""

    def __init__(
        self,
        model: FleetModel,
        value_keys: re.Pattern[str],
        transports: Iterable[str],
        extra_collectors: Iterable[Collector] = (),
        *,
        messages: MessageLabels = DEFAULT_MESSAGE_LABELS,
        external_url: str | None = None,
    ) -> None:
        """Render `model`, exporting key-values whose key fully matches `value_keys`.

        `messages` and `external_url` as for `FleetCollector`. `extra_collectors` (small ones: the event
        history's, the Icinga 2 push's) are rendered by prometheus-client and appended after the fleet:
        what a registry with the fleet's collector first, then them, renders.
        """
        self.assembler = ExpositionAssembler(transports, extra_collectors, external_url)
        self._model = model
        self._value_keys = value_keys
        self._messages = messages
        self._robots: dict[str, _RobotLines] = {}
        self._lock = threading.Lock()

    def render(self) -> bytes:
        """The exposition of the fleet now."""
        return self.assembler.assemble([self.render_part()])

    def render_part(self) -> ExpositionPart:
        """The model's series and counters, for an assembler to join with other models' (workers')."""
        with self._lock:
            return self._render(self._model.snapshot())

    def _render(self, snapshot: FleetSnapshot) -> ExpositionPart:
        render = _RenderCache(NumericValues(self._value_keys), self._messages)
        previous, current = self._robots, {}
        levels, changes, values, messages = [], [], [], []
        robot_level, robot_up, last_message = [], [], []
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
            if robot.last_message is not None:
                last_message.append(
                    f"ros_diagnostics_robot_last_message_timestamp_seconds{label}"
                    f"{go_float(robot.last_message)}\n"
                )
        self._robots = current
        return ExpositionPart(
            len(current),
            (
                b"".join(levels),
                "".join(robot_level).encode(),
                "".join(robot_up).encode(),
                "".join(last_message).encode(),
                b"".join(changes),
                b"".join(values),
                b"".join(messages),
            ),
            dict(snapshot.message_counts),
            dict(snapshot.dropped_statuses),
            snapshot.truncated_strings,
            dict(snapshot.source_errors),
        )


# The per-robot and per-component families, in exposition order: an `ExpositionPart` holds their lines.
FLEET_FAMILIES = (
    "ros_diagnostics_level",
    "ros_diagnostics_robot_level",
    "ros_diagnostics_robot_up",
    "ros_diagnostics_robot_last_message_timestamp_seconds",
    "ros_diagnostics_level_changes",
    "ros_diagnostics_value",
    "ros_diagnostics_status_message",
)


@dataclass(frozen=True, slots=True)
class ExpositionPart:
    """The rendered series of one model (a worker's robots): lines per fleet family, and its counters."""

    robots: int
    families: tuple[bytes, ...]  # the lines of each of FLEET_FAMILIES, without the header
    message_counts: dict[tuple[str, str], int]
    dropped_statuses: dict[str, int]
    truncated_strings: int
    source_errors: dict[tuple[str, str], int]


class ExpositionAssembler:
    """Joins parts (one per worker, robots disjoint) into one exposition; counters are summed."""

    def __init__(
        self,
        transports: Iterable[str],
        extra_collectors: Iterable[Collector] = (),
        external_url: str | None = None,
    ) -> None:
        """Add zero message counts for `transports`, then append `extra_collectors` and the web info."""
        self._extra = CollectorRegistry(auto_describe=False)
        for collector in extra_collectors:
            self._extra.register(collector)
        self._transports = tuple(transports)
        self._web_info = (
            ""
            if external_url is None
            else f'overseer_web_info{{external_url="{escape_label_value(external_url)}"}} 1.0\n'
        )
        self._headers = {
            metric.name: _header(metric.name, metric.type, metric.documentation)
            for metric in _Families.create().all()
        }

    def assemble(self, parts: Sequence[ExpositionPart]) -> bytes:
        """The whole exposition: each family's header, then every part's lines of it; then the counters."""
        headers = self._headers
        message_totals: Counter[tuple[str, str]] = Counter()
        dropped: Counter[str] = Counter()
        errors: Counter[tuple[str, str]] = Counter()
        for part in parts:
            message_totals.update(part.message_counts)
            dropped.update(part.dropped_statuses)
            errors.update(part.source_errors)
        truncated = sum(part.truncated_strings for part in parts)
        tail = [headers["overseer_messages"]]
        for (transport, result), count in message_counts(message_totals, self._transports):
            tail.append(
                f'overseer_messages_total{{result="{escape_label_value(result)}",'
                f'transport="{escape_label_value(transport)}"}} {go_float(float(count))}\n'
            )
        tail.append(headers["overseer_statuses_dropped"])
        for reason in DROP_REASONS:
            dropped_count = go_float(float(dropped[reason]))
            tail.append(f'overseer_statuses_dropped_total{{reason="{reason}"}} {dropped_count}\n')
        tail.append(headers["overseer_strings_truncated"])
        tail.append(f"overseer_strings_truncated_total {go_float(float(truncated))}\n")
        tail.append(headers["overseer_source_errors"])
        for (transport, reason), count in sorted(errors.items()):
            tail.append(
                f'overseer_source_errors_total{{reason="{escape_label_value(reason)}",'
                f'transport="{escape_label_value(transport)}"}} {go_float(float(count))}\n'
            )
        tail.append(headers["overseer_build_info"])
        tail.append(
            f'overseer_build_info{{codec="{compiled.implementation()}",'
            f'version="{escape_label_value(__version__)}"}} 1.0\n'
        )
        tail.append(headers["overseer_web_info"])
        tail.append(self._web_info)
        body: list[bytes] = []
        for index, family in enumerate(FLEET_FAMILIES):
            body.append(headers[family].encode())
            body.extend(part.families[index] for part in parts)
        body.append("".join(tail).encode())
        body.append(generate_latest(self._extra))  # joined here, not appended: no copy of the whole body
        return b"".join(body)


def _lines_for(
    snapshot: FleetSnapshot, robot: RobotState, up: bool, cached: _RobotLines | None, render: _RenderCache
) -> _RobotLines:
    if cached is not None and cached.revision == robot.revision:
        other_updates = cached.other_updates
    else:
        components = robot.components
        other_updates = sorted(components[key].last_update for key in robot.missing)
    horizon = snapshot.taken_at - snapshot.limits.stale_after
    message_stale = not snapshot.fresh(robot.last_message)
    signature = (robot.revision, up, message_stale, bisect.bisect_left(other_updates, horizon))
    if cached is not None and cached.signature == signature:
        return cached
    # Only the bytes are kept between scrapes (memory is the limit at 100,000 components); the
    # per-render caches make rendering cheap, since a fleet repeats its names, keys and values.
    escape, number, pairs, message_label = render.escape, render.number, render.numbers.pairs, render.message
    message_prefix = "ros_diagnostics_status_message{"
    robot_label = f'robot="{escape(robot.name)}"'
    reusable = cached.components if cached is not None and cached.signature[1:3] == signature[1:3] else ()
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
        message = message_label(component)
        lines.add(
            index,
            f"ros_diagnostics_level{labels}{_LEVEL_VALUES[levels[index]]}\n".encode(),
            f"ros_diagnostics_level_changes_total{labels}{number(float(component.level_changes))}\n".encode(),
            values.encode(),
            b""
            if message is None
            else f'{message_prefix}{identity},message="{message}",{robot_label}}} 1.0\n'.encode(),
        )
    level_lines, changes, values_lines, message_lines, offsets = lines.finish(len(levels))
    # A component missing from the latest message renders by its own time: never copied (None).
    records = (
        tuple(component if key not in missing else None for key, component in items)
        if missing
        else tuple(robot.components.values())
    )
    return _RobotLines(
        signature,
        robot.revision,
        other_updates,
        worst(levels) if up else Level.STALE,
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

    def finish(self, count: int) -> tuple[bytes, bytes, bytes, bytes, array[int]]:
        """The families' bytes for `count` components, and where every component's lines start."""
        self._copy_cached(count)
        levels, changes, values, messages = (b"".join(pieces) for pieces in self._pieces)
        return levels, changes, values, messages, self._offsets

    def _copy_cached(self, stop: int) -> None:
        """Copy the cached lines of components `self._next` to `stop` (where they had the same index)."""
        if stop == self._next or self._cached is None:
            return
        cached, first, last = self._cached, FAMILIES * self._next, FAMILIES * stop
        old = cached.offsets
        shifts = []
        for family, text in enumerate((cached.levels, cached.changes, cached.values, cached.messages)):
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


class _RenderCache:
    """Memoized escaping and number formatting for one render."""

    def __init__(self, numbers: NumericValues, messages: MessageLabels) -> None:
        self.numbers = numbers
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


def _header(name: str, kind: str, documentation: str) -> str:
    exposed = name + "_total" if kind == "counter" else name
    help_text = documentation.replace("\\", r"\\").replace("\n", r"\n")
    return f"# HELP {exposed} {help_text}\n# TYPE {exposed} {kind}\n"
