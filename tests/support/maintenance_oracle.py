"""The test oracle of the maintenance families: prometheus-client's collector over the same schedule.

Production writes these lines itself and keeps them (`overseer.serve.maintenance_lines`); this collector
builds fresh families at every scrape, the straightforward way, so the tests can hold the two
byte-identical in the text format and in OpenMetrics.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Iterator

from prometheus_client.metrics_core import GaugeMetricFamily, Metric
from prometheus_client.registry import Collector

from overseer.maintenance.schedule import MaintenanceSchedule


class MaintenanceOracle(Collector):
    """The maintenance state of every robot `robots()` names (the fleet's), and the windows counted."""

    def __init__(self, schedule: MaintenanceSchedule, robots: Callable[[], Iterable[str]]) -> None:
        """Judge `robots()` (the fleet's robot names now) against `schedule`'s windows."""
        self._schedule = schedule
        self._robots = robots

    def collect(self) -> Iterator[Metric]:
        """The families now."""
        now = self._schedule.clock()
        windows = self._schedule.windows(now)
        active = [window for window in windows if window.active(now)]
        in_window = GaugeMetricFamily(
            "ros_diagnostics_robot_maintenance",
            "1 while the robot is in a maintenance window, else 0.",
            labels=["robot"],
        )
        ends = GaugeMetricFamily(
            "ros_diagnostics_robot_maintenance_end_timestamp_seconds",
            "Unix time the maintenance window the robot is in ends.",
            labels=["robot"],
            unit="seconds",
        )
        for robot in sorted(set(self._robots())):
            state = self._schedule.state(robot, active)
            in_window.add_metric([robot], 0.0 if state is None else 1.0)
            if state is not None:
                ends.add_metric([robot], state.until)
        counts = GaugeMetricFamily(
            "overseer_maintenance_windows",
            "Maintenance windows by state: active, scheduled.",
            labels=["state"],
        )
        counts.add_metric(["active"], float(len(active)))
        counts.add_metric(["scheduled"], float(sum(1 for window in windows if window.start > now)))
        yield from (in_window, ends, counts)
