"""The inventory's own metrics, named as Prometheus names those of its configuration reloads."""

from __future__ import annotations

from collections.abc import Iterator

from prometheus_client.metrics_core import GaugeMetricFamily, Metric
from prometheus_client.registry import Collector

from overseer.inventory.reload import InventoryReloader


class InventoryCollector(Collector):
    """Whether the last reload of the inventory file worked, when the last good one was, robots listed."""

    def __init__(self, reloader: InventoryReloader) -> None:
        """Report on `reloader`."""
        self._reloader = reloader

    def collect(self) -> Iterator[Metric]:
        """The three gauges now."""
        reloader = self._reloader
        yield GaugeMetricFamily(
            "overseer_inventory_last_reload_successful",
            "1 when the last reading of the inventory file succeeded, 0 when it was refused.",
            value=1.0 if reloader.last_successful else 0.0,
        )
        yield GaugeMetricFamily(
            "overseer_inventory_last_reload_success_timestamp_seconds",
            "Unix time of the last successful reading of the inventory file.",
            value=reloader.last_success_at,
        )
        yield GaugeMetricFamily(
            "overseer_inventory_robots",
            "Robots listed in the inventory in force.",
            value=float(len(reloader.inventory.robots)),
        )
