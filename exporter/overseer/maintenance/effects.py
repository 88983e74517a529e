"""What the outputs elsewhere made of the windows (silences, downtimes), counted for /metrics.

# HELP overseer_maintenance_effects_total Silences and downtimes made or removed, by target and action.
# TYPE overseer_maintenance_effects_total counter
overseer_maintenance_effects_total{target="alertmanager",action="created"} 3.0
"""

from __future__ import annotations

import threading
from collections.abc import Iterable, Iterator

from prometheus_client.metrics_core import CounterMetricFamily, GaugeMetricFamily, Metric
from prometheus_client.registry import Collector

CREATED, REMOVED = "created", "removed"


class EffectStats:
    """One target's counts (`alertmanager`, `icinga2`); the sync loop updates them, /metrics reads them."""

    def __init__(self, target: str) -> None:
        """Start with nothing done."""
        self.target = target
        self._lock = threading.Lock()
        self._actions = {CREATED: 0, REMOVED: 0}
        self._failures: dict[str, int] = {}
        self._pending = 0
        self._last_success = 0.0

    def done(self, action: str) -> None:
        """One silence or downtime was `action` (created, removed)."""
        with self._lock:
            self._actions[action] += 1

    def failed(self, reason: str) -> None:
        """One request failed for `reason` (`connection`, `timeout`, `http_500`...); it is retried."""
        with self._lock:
            self._failures[reason] = self._failures.get(reason, 0) + 1

    def synced(self, at: float, pending: int) -> None:
        """A sync ended at unix time `at` (`pending`: what it could not do yet, 0 when all is done)."""
        with self._lock:
            self._pending = pending
            if pending == 0:
                self._last_success = at

    def read(self) -> tuple[dict[str, int], dict[str, int], int, float]:
        """Actions, failures by reason, what waits, and the last complete sync's unix time (0: none)."""
        with self._lock:
            return dict(self._actions), dict(self._failures), self._pending, self._last_success


class EffectsCollector(Collector):
    """`overseer_maintenance_effects_*` for every target configured."""

    def __init__(self, targets: Iterable[EffectStats]) -> None:
        """Read each of `targets` at every collection."""
        self._targets = list(targets)

    def collect(self) -> Iterator[Metric]:
        """The families now."""
        actions = CounterMetricFamily(
            "overseer_maintenance_effects",
            "Silences and downtimes made or removed for maintenance windows, by target and action.",
            labels=["target", "action"],
        )
        failures = CounterMetricFamily(
            "overseer_maintenance_effect_failures",
            "Requests for maintenance windows that failed (and are retried), by target and reason.",
            labels=["target", "reason"],
        )
        pending = GaugeMetricFamily(
            "overseer_maintenance_effects_pending",
            "Silences or downtimes still to be made or removed, waiting for their target to answer.",
            labels=["target"],
        )
        last = GaugeMetricFamily(
            "overseer_maintenance_last_sync_timestamp_seconds",
            "Unix time the target last held every silence or downtime it should (0: not yet).",
            labels=["target"],
            unit="seconds",
        )
        for stats in self._targets:
            done, failed, waiting, at = stats.read()
            for action in sorted(done):
                actions.add_metric([stats.target, action], float(done[action]))
            for reason in sorted(failed):
                failures.add_metric([stats.target, reason], float(failed[reason]))
            pending.add_metric([stats.target], float(waiting))
            last.add_metric([stats.target], at)
        yield from (actions, failures, pending, last)
