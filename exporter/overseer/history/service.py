"""The event history of one exporter: the store with its metrics.

The fleet feeds it (`Fleet`'s implementations are built with `store.add` as their event sink): with
ingest workers, each worker watches its own model and sends its events to the exporter's one store.
"""

from __future__ import annotations

import logging

from overseer.config.events import EventsConfig
from overseer.history.metrics import EventsCollector
from overseer.history.store import EventStore, StoreSettings

log = logging.getLogger(__name__)


class EventHistory:
    """The event store of the exporter and its metrics, open while started."""

    def __init__(self, config: EventsConfig, log_events: bool = False) -> None:
        """Open the store for `config` (degraded on failure)."""
        self.store = EventStore(StoreSettings(config.path, config.retention, config.max_size, log_events))
        self.collector = EventsCollector(self.store)

    def start(self) -> None:
        """Start writing what is added to the store."""
        self.store.start()
        if self.store.available:
            log.info("recording fleet events in %s", self.store.settings.path)

    def stop(self) -> None:
        """Write what is queued and close the store."""
        self.store.stop()
