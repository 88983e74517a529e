"""The event history of one exporter: the store with its metrics, and the watch that feeds it from a model.

With ingest workers, each worker watches its own model and sends its events to the exporter's one store.
"""

from __future__ import annotations

import logging
import threading

from overseer.config.events import EventsConfig
from overseer.history.detector import EventSink, TransitionDetector
from overseer.history.metrics import EventsCollector
from overseer.history.store import EventStore, StoreSettings
from overseer.model import FleetModel

log = logging.getLogger(__name__)

CHECK_INTERVAL_SECONDS = 1.0


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


class TransitionWatch:
    """Detects a model's transitions while started: its level listener, and a check every second."""

    def __init__(self, model: FleetModel, sink: EventSink) -> None:
        """Watch `model`, sending its events to `sink`."""
        self.detector = TransitionDetector(model.limits, sink)
        self._model = model
        self._stopping = threading.Event()
        self._thread: threading.Thread | None = None

    def start(self) -> None:
        """Listen to the model, and check its snapshots every `CHECK_INTERVAL_SECONDS`."""
        self._model.set_level_listener(self.detector.on_level_changes)
        self._thread = threading.Thread(target=self._check_loop, name="event-detector", daemon=True)
        self._thread.start()

    def stop(self) -> None:
        """Stop detecting."""
        self._stopping.set()
        self._model.set_level_listener(None)
        if self._thread is not None:
            self._thread.join(timeout=5)

    def _check_loop(self) -> None:
        while not self._stopping.wait(CHECK_INTERVAL_SECONDS):
            try:
                self.detector.check(self._model.snapshot())
            except Exception:  # a bug here must not end event detection for good
                log.exception("event detection failed")
