"""The test oracle of /metrics: prometheus-client's own collector over the same fleet model.

Production renders the exposition itself, from cached per-robot lines (`overseer.serve.exposition`); this
collector builds fresh prometheus-client families from a snapshot, the straightforward way, so that the
tests can hold the two byte-identical in the text format and in OpenMetrics.
"""

from __future__ import annotations

import re
from collections.abc import Iterable, Iterator

from prometheus_client.exposition import generate_latest as generate_text
from prometheus_client.metrics_core import CounterMetricFamily, GaugeMetricFamily, Metric
from prometheus_client.openmetrics.exposition import generate_latest as generate_openmetrics
from prometheus_client.openmetrics.parser import text_string_to_metric_families as strict_openmetrics_parser
from prometheus_client.registry import Collector, CollectorRegistry

from overseer import __version__
from overseer.codec import compiled
from overseer.fleet import metric_families as contract
from overseer.fleet.message_labels import DEFAULT_MESSAGE_LABELS, MessageLabels
from overseer.fleet.metric_values import DROP_REASONS, NumericValues, message_counts
from overseer.levels import Level
from overseer.model import FleetModel
from overseer.model.state import learned_period


def family(spec: contract.MetricFamily) -> Metric:
    """An empty prometheus-client family for one family of the contract."""
    kind = CounterMetricFamily if spec.kind == "counter" else GaugeMetricFamily
    name = spec.name[: -len(spec.unit) - 1] if spec.unit else spec.name  # prometheus-client adds the unit
    return kind(name, spec.documentation, labels=list(spec.labels), unit=spec.unit)


class OracleCollector(Collector):
    """The metric contract from fresh families over one snapshot of `model`."""

    def __init__(
        self,
        model: FleetModel,
        value_keys: re.Pattern[str],
        transports: Iterable[str],
        *,
        messages: MessageLabels = DEFAULT_MESSAGE_LABELS,
        external_url: str | None = None,
        level_changes: bool = True,
    ) -> None:
        """Collect from `model`, exporting key-values whose key fully matches `value_keys`."""
        self._level_changes = level_changes
        self._model = model
        self._value_keys = value_keys
        self._transports = tuple(transports)
        self._messages = messages
        self._external_url = external_url

    def describe(self) -> Iterator[Metric]:
        """The families, empty."""
        yield from (family(spec) for spec in contract.CONTRACT_FAMILIES)

    def collect(self) -> Iterator[Metric]:
        """Fresh families from one snapshot of the fleet."""
        snapshot = self._model.snapshot()
        families = {spec.name: family(spec) for spec in contract.CONTRACT_FAMILIES}

        def add(spec: contract.MetricFamily, labels: Iterable[str], value: float) -> None:
            metric = families[spec.name]
            assert isinstance(metric, GaugeMetricFamily | CounterMetricFamily)
            metric.add_metric(list(labels), value)

        numbers = NumericValues(self._value_keys)
        for robot in snapshot.robots:
            up = snapshot.robot_up(robot)
            add(contract.ROBOT_UP, [robot.name], 1.0 if up else 0.0)
            add(contract.ROBOT_LEVEL, [robot.name], float(snapshot.robot_level(robot)))
            if robot.last_message_wall is not None:
                add(contract.LAST_MESSAGE, [robot.name], robot.last_message_wall)
            period = learned_period(robot)
            if period is not None:
                add(contract.PERIOD, [robot.name], round(period, 3))
            inventory_labels = dict(robot.listing.labels) if robot.listing is not None else {}
            families[contract.ROBOT_INFO.name].add_sample(
                contract.ROBOT_INFO.name, {"robot": robot.name, **inventory_labels}, 1.0
            )
            at_level = dict.fromkeys(Level, 0)
            for key, component in robot.components.items():
                labels = (robot.name, component.name, component.hardware_id)
                level = snapshot.component_level(robot, key, component, up)
                at_level[level] += 1
                add(contract.LEVEL, labels, float(level))
                if self._level_changes:
                    add(contract.LEVEL_CHANGES, labels, float(component.level_changes))
                for value_key, number in numbers.pairs(component.values):
                    add(contract.VALUE, (*labels, value_key), number)
                message = self._messages.label(component)
                if message is not None:
                    add(contract.STATUS_MESSAGE, (*labels, level.name, message), 1.0)
            for level, count in at_level.items():
                add(contract.ROBOT_COMPONENTS, [robot.name, level.name], float(count))
            add(contract.ROBOT_LEVEL_CHANGES, [robot.name], float(robot.level_changes))
        for (transport, result), count in message_counts(snapshot.message_counts, self._transports):
            add(contract.MESSAGES, [transport, result], float(count))
        for reason in DROP_REASONS:
            add(contract.STATUSES_DROPPED, [reason], float(snapshot.dropped_statuses.get(reason, 0)))
        add(contract.STRINGS_TRUNCATED, [], float(snapshot.truncated_strings))
        for (transport, reason), count in sorted(snapshot.source_errors.items()):
            add(contract.SOURCE_ERRORS, [transport, reason], float(count))
        for reason in contract.FORGET_REASONS:
            add(contract.ROBOTS_FORGOTTEN, [reason], float(snapshot.forgotten_counts.get(reason, 0)))
        add(contract.BUILD_INFO, [__version__, compiled.implementation()], 1.0)
        if self._external_url is not None:
            add(contract.WEB_INFO, [self._external_url], 1.0)
        yield from families.values()


def oracle_registry(*collectors: Collector) -> CollectorRegistry:
    """A registry of `collectors` in order, as the exporter appends its extra collectors to the fleet's."""
    registry = CollectorRegistry(auto_describe=True)
    for collector in collectors:
        registry.register(collector)
    return registry


def oracle_text(registry: CollectorRegistry) -> bytes:
    """prometheus-client's text format 0.0.4 of `registry`."""
    return generate_text(registry)


def oracle_openmetrics(registry: CollectorRegistry) -> bytes:
    """prometheus-client's OpenMetrics 1.0.0 of `registry`."""
    return bytes(generate_openmetrics(registry))  # type: ignore[no-untyped-call]


def parse_openmetrics(text: str) -> list[Metric]:
    """`text` read by prometheus-client's strict OpenMetrics parser (which raises on anything malformed)."""
    return list(strict_openmetrics_parser(text))  # type: ignore[no-untyped-call]
