"""The /metrics view: one custom collector that turns a fleet snapshot into the metric contract.

Every scrape builds fresh metric families from one snapshot, so a robot that is forgotten simply stops
appearing, and a scrape never sees half of an update.

    # HELP ros_diagnostics_level Component level: 0 OK, 1 WARN, 2 ERROR, 3 STALE.
    # TYPE ros_diagnostics_level gauge
    ros_diagnostics_level{robot="robot1",component="/Power/Robot Battery",hardware_id=""} 0.0
"""

from __future__ import annotations

import math
import re
from collections.abc import Iterable, Iterator, Mapping
from dataclasses import dataclass, fields

from prometheus_client.metrics_core import CounterMetricFamily, GaugeMetricFamily, Metric
from prometheus_client.registry import Collector

from overseer import __version__
from overseer.codec import compiled
from overseer.model import FleetModel, FleetSnapshot, RobotState
from overseer.serve.message_labels import DEFAULT_MESSAGE_LABELS, MessageLabels

MESSAGE_RESULTS = ("received", "decode_error", "dropped")
DROP_REASONS = ("robot_limit", "component_limit", "value_limit", "invalid_level")

_COMPONENT_LABELS = ["robot", "component", "hardware_id"]
_LEADING_NUMBER = re.compile(r"\s*([-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)")
_BOOLEANS = {"true": 1.0, "false": 0.0, "True": 1.0, "False": 0.0}


def numeric_value(text: str) -> float | None:
    """The number a key-value's text carries (`12.5`, `12.5 V`, `True`), or None for other text."""
    try:
        return float(text)
    except ValueError:
        pass
    if text in _BOOLEANS:
        return _BOOLEANS[text]
    match = _LEADING_NUMBER.match(text)
    if match is None:
        return None
    value = float(match.group(1))
    return value if math.isfinite(value) else None


class FleetCollector(Collector):
    """Exports the fleet model as the metric contract of ARCHITECTURE.md."""

    def __init__(
        self,
        model: FleetModel,
        value_keys: re.Pattern[str],
        transports: Iterable[str],
        *,
        messages: MessageLabels = DEFAULT_MESSAGE_LABELS,
        external_url: str | None = None,
    ) -> None:
        """Collect from `model`, exporting key-values whose key fully matches `value_keys`.

        `messages` chooses the components with a status-message series; `external_url`, when given,
        is exported in `overseer_web_info` for alert links.
        """
        self._model = model
        self._value_keys = value_keys
        self._transports = tuple(transports)
        self._messages = messages
        self._external_url = external_url

    def describe(self) -> Iterator[Metric]:
        """The families this collector exports, without taking a snapshot."""
        yield from _Families.create().all()

    def collect(self) -> Iterator[Metric]:
        """Fresh families from one snapshot of the fleet."""
        snapshot = self._model.snapshot()
        families = _Families.create()
        numbers = NumericValues(self._value_keys)
        for robot in snapshot.robots:
            name = robot.name
            families.robot_up.add_metric([name], 1.0 if snapshot.robot_up(robot) else 0.0)
            families.robot_level.add_metric([name], float(snapshot.robot_level(robot)))
            if robot.last_message is not None:
                families.last_message.add_metric([name], robot.last_message)
            samples = robot_samples(snapshot, robot, numbers, self._messages)
            for labels, sample in samples.levels:
                families.level.add_metric(list(labels), sample)
            for labels, sample in samples.changes:
                families.changes.add_metric(list(labels), sample)
            for value_labels, sample in samples.values:
                families.value.add_metric(list(value_labels), sample)
            for message_labels in samples.messages:
                families.status_message.add_metric(list(message_labels), 1.0)
        for (transport, result), count in message_counts(snapshot.message_counts, self._transports):
            families.messages.add_metric([transport, result], float(count))
        for reason in DROP_REASONS:
            families.dropped.add_metric([reason], float(snapshot.dropped_statuses.get(reason, 0)))
        families.truncated.add_metric([], float(snapshot.truncated_strings))
        for (transport, reason), count in sorted(snapshot.source_errors.items()):
            families.source_errors.add_metric([transport, reason], float(count))
        families.build.add_metric([__version__, compiled.implementation()], 1.0)
        if self._external_url is not None:
            families.web_info.add_metric([self._external_url], 1.0)
        yield from families.all()


class NumericValues:
    """Which key-values are exported, and their numbers; caches the parse of each distinct text."""

    def __init__(self, value_keys: re.Pattern[str]) -> None:
        """Export keys that fully match `value_keys`."""
        self._allowed = value_keys.fullmatch
        self._parsed: dict[str, float | None] = {}

    def pairs(self, values: tuple[tuple[str, str], ...]) -> Iterator[tuple[str, float]]:
        """(key, number) for each allowed key with a numeric value, the first of any repeated key."""
        seen: set[str] = set()
        for key, text in values:
            if key in seen or not self._allowed(key):
                continue
            seen.add(key)
            if text in self._parsed:
                number = self._parsed[text]
            else:
                number = self._parsed[text] = numeric_value(text)
            if number is not None:
                yield key, number


@dataclass(frozen=True, slots=True)
class RobotSamples:
    """One robot's per-component samples: (labels, value) in the contract's label order."""

    levels: list[tuple[tuple[str, str, str], float]]
    changes: list[tuple[tuple[str, str, str], float]]
    values: list[tuple[tuple[str, str, str, str], float]]
    messages: list[tuple[str, str, str, str]]  # status-message series, value 1


def robot_samples(
    snapshot: FleetSnapshot,
    robot: RobotState,
    numbers: NumericValues,
    messages: MessageLabels = DEFAULT_MESSAGE_LABELS,
) -> RobotSamples:
    """The per-component samples of one robot at the snapshot's time."""
    up = snapshot.robot_up(robot)
    name = robot.name
    samples = RobotSamples([], [], [], [])
    for key, component in robot.components.items():
        labels = (name, component.name, component.hardware_id)
        samples.levels.append((labels, float(snapshot.component_level(robot, key, component, up))))
        samples.changes.append((labels, float(component.level_changes)))
        for value_key, number in numbers.pairs(component.values):
            samples.values.append(((*labels, value_key), number))
        message = messages.label(component)
        if message is not None:
            samples.messages.append((*labels, message))
    return samples


def message_counts(
    counted: Mapping[tuple[str, str], int], transports: Iterable[str]
) -> list[tuple[tuple[str, str], int]]:
    """Message counts by (transport, result), with zeros for every result of the active transports."""
    counts = dict(counted)
    for transport in transports:
        for result in MESSAGE_RESULTS:
            counts.setdefault((transport, result), 0)
    return sorted(counts.items())


@dataclass(frozen=True)
class _Families:
    """Empty metric families of the contract, in exposition order."""

    level: GaugeMetricFamily
    robot_level: GaugeMetricFamily
    robot_up: GaugeMetricFamily
    last_message: GaugeMetricFamily
    changes: CounterMetricFamily
    value: GaugeMetricFamily
    status_message: GaugeMetricFamily
    messages: CounterMetricFamily
    dropped: CounterMetricFamily
    truncated: CounterMetricFamily
    source_errors: CounterMetricFamily
    build: GaugeMetricFamily
    web_info: GaugeMetricFamily

    def all(self) -> tuple[Metric, ...]:
        """Every family, in exposition order."""
        return tuple(getattr(self, f.name) for f in fields(self))

    @classmethod
    def create(cls) -> _Families:
        """Fresh, empty families."""
        return cls(
            GaugeMetricFamily(
                "ros_diagnostics_level",
                "Component level: 0 OK, 1 WARN, 2 ERROR, 3 STALE.",
                labels=_COMPONENT_LABELS,
            ),
            GaugeMetricFamily(
                "ros_diagnostics_robot_level",
                "Worst component level of the robot (ERROR > WARN > STALE > OK); 3 while the robot is down.",
                labels=["robot"],
            ),
            GaugeMetricFamily(
                "ros_diagnostics_robot_up",
                "1 while the robot's messages arrive within robot_timeout.",
                labels=["robot"],
            ),
            GaugeMetricFamily(
                "ros_diagnostics_robot_last_message_timestamp_seconds",
                "Unix time of the robot's last diagnostics message.",
                labels=["robot"],
            ),
            CounterMetricFamily(
                "ros_diagnostics_level_changes",
                "Changes of a component's reported level (flapping).",
                labels=_COMPONENT_LABELS,
            ),
            GaugeMetricFamily(
                "ros_diagnostics_value",
                "Numeric key-values of a component's status, for the keys the configuration allows.",
                labels=[*_COMPONENT_LABELS, "key"],
            ),
            GaugeMetricFamily(
                "ros_diagnostics_status_message",
                "A component's status message as a label, cut to metrics.message_label_length; always 1. "
                "Only for the components metrics.message_labels chooses (default: reported not OK).",
                labels=[*_COMPONENT_LABELS, "message"],
            ),
            CounterMetricFamily(
                "overseer_messages",
                "Diagnostics messages by transport and result: received, decode_error or dropped.",
                labels=["transport", "result"],
            ),
            CounterMetricFamily(
                "overseer_statuses_dropped",
                "Statuses and key-values dropped by the fleet model's caps, by reason.",
                labels=["reason"],
            ),
            CounterMetricFamily(
                "overseer_strings_truncated", "Names, messages and key-values cut to max_string_length."
            ),
            CounterMetricFamily(
                "overseer_source_errors",
                "Failures to reach robots by transport and reason, such as an unreachable ROS 1 master.",
                labels=["transport", "reason"],
            ),
            GaugeMetricFamily(
                "overseer_build_info",
                "Overseer's version and status decoder (compiled, or python without one); always 1.",
                labels=["version", "codec"],
            ),
            GaugeMetricFamily(
                "overseer_web_info",
                "The URL users reach this exporter at (web.external_url), for links in alerts; always 1.",
                labels=["external_url"],
            ),
        )
