"""How long `/metrics` waited for the fleet's series, scrape after scrape.

Prometheus's `scrape_duration_seconds` counts everything from its request to the last sample stored; this
is the largest part of the exporter's share at a large fleet: rendering what changed since the render
before, and waiting for a render under way (a render ahead's pass, another scrape). Not counted: writing
the exporter's own families after the series (tens of milliseconds) and sending the answer. Set beside
Prometheus's figure, it tells a slow render from a slow Prometheus.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Iterator
from typing import TypeVar

from prometheus_client.metrics_core import GaugeMetricFamily, Metric, SummaryMetricFamily
from prometheus_client.registry import Collector

T = TypeVar("T")


class RenderTiming:
    """The renders of the fleet's series for `/metrics`: how many, their seconds in all, the last one's."""

    def __init__(self, clock: Callable[[], float] = time.monotonic) -> None:
        """Count none yet; time by `clock` (seconds)."""
        self._clock = clock
        self._lock = threading.Lock()
        self.count = 0
        self.total_seconds = 0.0
        self.last_seconds = 0.0

    def timed(self, render: Callable[[], T]) -> T:
        """`render()`, counted with how long it took when it returns (a render that raises is not)."""
        started = self._clock()
        result = render()
        seconds = self._clock() - started
        with self._lock:
            self.count += 1
            self.total_seconds += seconds
            self.last_seconds = seconds
        return result

    def read(self) -> tuple[int, float, float]:
        """The renders counted, their seconds in all, and the last one's, read together."""
        with self._lock:
            return self.count, self.total_seconds, self.last_seconds


class RenderTimingCollector(Collector):
    """`overseer_exposition_render_duration_seconds` and `overseer_exposition_last_render_seconds`."""

    def __init__(self, timing: RenderTiming) -> None:
        """Tell of `timing`."""
        self._timing = timing

    def collect(self) -> Iterator[Metric]:
        """The families, read now: a scrape's own render is counted, its series being rendered first."""
        count, total, last = self._timing.read()
        yield SummaryMetricFamily(
            "overseer_exposition_render_duration_seconds",
            "Time /metrics waited for the fleet's series to be rendered, before the rest of its answer.",
            count_value=count,
            sum_value=total,
        )
        latest = GaugeMetricFamily(
            "overseer_exposition_last_render_seconds",
            "Time the last /metrics waited for the fleet's series to be rendered.",
        )
        latest.add_metric([], last)
        yield latest
