"""The event history of one exporter: the store with its metrics.

The fleet feeds it (`Fleet`'s implementations are built with `store.add` as their event sink): with
ingest workers, each worker watches its own model and sends its events to the exporter's one store.
"""

from __future__ import annotations

import logging

from overseer.config.events import EventsConfig
from overseer.history.metrics import EventsCollector
from overseer.history.store import DEFAULT_QUEUE_LIMIT, EventStore, StoreSettings

log = logging.getLogger(__name__)

# Events that may wait for the writer, a robot of the fleet's cap: a fleet first heard (the exporter
# started beside it) gives one event a component at once, 500,000 for 10,000 robots of 50.
QUEUED_EVENTS_PER_ROBOT = 64


class EventHistory:
    """The event store of the exporter and its metrics, open while started."""

    def __init__(self, config: EventsConfig, log_events: bool = False, max_robots: int = 0) -> None:
        """Open the store for `config` (degraded on failure), its queue sized for `max_robots`."""
        queue_limit = max(DEFAULT_QUEUE_LIMIT, QUEUED_EVENTS_PER_ROBOT * max_robots)
        settings = StoreSettings(config.path, config.retention, config.max_size, log_events, queue_limit)
        self.store = EventStore(settings)
        self.collector = EventsCollector(self.store)

    def start(self) -> None:
        """Start writing what is added to the store."""
        self.store.start()
        if self.store.available:
            log.info("recording fleet events in %s", self.store.settings.path)

    def stop(self) -> None:
        """Write what is queued and close the store."""
        self.store.stop()
