"""The event history's own metrics: events written and dropped, the database's size, whether it writes.

A collector of its own, registered after the fleet's: `/metrics` appends its rendering to the fleet's,
in that order, so the hand-made exposition and prometheus-client's stay byte-identical.
"""

from __future__ import annotations

from collections.abc import Iterator

from prometheus_client.metrics_core import CounterMetricFamily, GaugeMetricFamily, Metric
from prometheus_client.registry import Collector

from overseer.history.store import DROP_REASONS, EventStore


class EventsCollector(Collector):
    """Exports an `EventStore`'s counts and size."""

    def __init__(self, store: EventStore) -> None:
        """Report on `store`."""
        self._store = store

    def describe(self) -> Iterator[Metric]:
        """The families, empty."""
        yield from _families()

    def collect(self) -> Iterator[Metric]:
        """The families with the store's figures now."""
        stats = self._store.stats()
        written, dropped, size, up = _families()
        written.add_metric([], float(stats.written))
        for reason in DROP_REASONS:
            dropped.add_metric([reason], float(stats.dropped.get(reason, 0)))
        size.add_metric([], float(stats.size_bytes))
        up.add_metric([], 1.0 if stats.up else 0.0)
        yield from (written, dropped, size, up)


def _families() -> tuple[CounterMetricFamily, CounterMetricFamily, GaugeMetricFamily, GaugeMetricFamily]:
    return (
        CounterMetricFamily("overseer_events_written", "Fleet events written to the event history."),
        CounterMetricFamily(
            "overseer_events_dropped",
            "Fleet events not written, by reason: queue_full, write_error, store_unavailable.",
            labels=["reason"],
        ),
        GaugeMetricFamily(
            "overseer_events_database_bytes",
            "Size of the event database on disk, write-ahead log included.",
            unit="bytes",
        ),
        GaugeMetricFamily(
            "overseer_events_store_up", "1 while events are being written; 0 when the database can't be used."
        ),
    )
