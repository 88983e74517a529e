"""The ingest workers' own metrics: how many, which are up, and how often each was restarted."""

from __future__ import annotations

from collections.abc import Iterator

from prometheus_client.metrics_core import CounterMetricFamily, GaugeMetricFamily, Metric
from prometheus_client.registry import Collector

from overseer.fleet.workers.pool import WorkerPool


class WorkerPoolCollector(Collector):
    """`overseer_ingest_workers`, `overseer_ingest_worker_up` and `overseer_ingest_worker_restarts_total`."""

    def __init__(self, pool: WorkerPool) -> None:
        """Tell of `pool`'s workers."""
        self._pool = pool

    def collect(self) -> Iterator[Metric]:
        """The families, read from the pool now."""
        pool = self._pool
        workers = GaugeMetricFamily("overseer_ingest_workers", "Worker processes sharing the ingest.")
        workers.add_metric([], float(pool.count))
        up = GaugeMetricFamily(
            "overseer_ingest_worker_up",
            "1 while the ingest worker runs and follows its robots, 0 while it is being restarted.",
            labels=["worker"],
        )
        restarts = CounterMetricFamily(
            "overseer_ingest_worker_restarts",
            "Times the ingest worker died (or hung) and was started again.",
            labels=["worker"],
        )
        for index in range(pool.count):
            up.add_metric([str(index)], 1.0 if pool.up(index) else 0.0)
            restarts.add_metric([str(index)], float(pool.restarts[index]))
        yield workers
        yield up
        yield restarts
