"""The push's own metrics: results delivered or not, the last success, what is waiting."""

from __future__ import annotations

import threading
from collections.abc import Iterator

from prometheus_client.metrics_core import CounterMetricFamily, GaugeMetricFamily, Metric
from prometheus_client.registry import Collector


class PushStats:
    """Counters the push loop updates and /metrics reads; thread-safe."""

    def __init__(self) -> None:
        """Start with nothing pushed."""
        self._lock = threading.Lock()
        self._results: dict[str, int] = {"ok": 0}
        self._last_success = 0.0
        self._pending = 0
        self._stages: dict[str, int] = {}

    def delivered(self, count: int, at: float) -> None:
        """`count` results were accepted at unix time `at`."""
        with self._lock:
            self._results["ok"] += count
            self._last_success = at

    def failed(self, reason: str) -> None:
        """One request failed for `reason` (`connection`, `timeout`, `tls`, `http_401`, `http_500`...)."""
        with self._lock:
            self._results[reason] = self._results.get(reason, 0) + 1

    def staged(self, result: str) -> None:
        """A config package stage was `ok` (loaded), `rejected` (invalid) or `refused` (not allowed)."""
        with self._lock:
            self._stages[result] = self._stages.get(result, 0) + 1

    def stages(self) -> dict[str, int]:
        """Stages of the config package by result."""
        with self._lock:
            return dict(self._stages)

    def set_pending(self, count: int) -> None:
        """How many results wait to be delivered (at most one per host and service)."""
        with self._lock:
            self._pending = count

    def read(self) -> tuple[dict[str, int], float, int]:
        """Counts by result, the last success's unix time (0: never) and the pending count."""
        with self._lock:
            return dict(self._results), self._last_success, self._pending


class PushCollector(Collector):
    """Exposes `PushStats` as `overseer_icinga2_*` metrics."""

    def __init__(self, stats: PushStats) -> None:
        """Read `stats` at every collection."""
        self._stats = stats

    def collect(self) -> Iterator[Metric]:
        """The push metrics now."""
        results, last_success, pending = self._stats.read()
        pushes = CounterMetricFamily(
            "overseer_icinga2_pushes",
            "Requests to Icinga 2 by result: ok (per check result delivered) or why one failed",
            labels=["result"],
        )
        for result in sorted(results):
            pushes.add_metric([result], float(results[result]))
        yield pushes
        stages = CounterMetricFamily(
            "overseer_icinga2_package_stages",
            "Stages of the exporter's Icinga 2 config package, registering or deleting robots at once, by "
            "result: ok, rejected (Icinga's validation failed) or refused (the ApiUser may not)",
            labels=["result"],
        )
        for result, count in sorted(self._stats.stages().items()):
            stages.add_metric([result], float(count))
        yield stages
        yield GaugeMetricFamily(
            "overseer_icinga2_last_success_timestamp_seconds",
            "Unix time of the last check result Icinga 2 accepted (0: none yet)",
            value=last_success,
            unit="seconds",
        )
        yield GaugeMetricFamily(
            "overseer_icinga2_pending_results",
            "Check results waiting for Icinga 2 (the latest one per host and service)",
            value=float(pending),
        )
