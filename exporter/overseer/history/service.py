"""The event history of one exporter: the detector fed by the model, the store, and the checking thread."""

from __future__ import annotations

import logging
import threading

from overseer.config import EventsConfig
from overseer.history.detector import TransitionDetector
from overseer.history.metrics import EventsCollector
from overseer.history.store import EventStore, StoreSettings
from overseer.model import FleetModel

log = logging.getLogger(__name__)

CHECK_INTERVAL_SECONDS = 1.0


class EventHistory:
    """Records the fleet's transitions in an `EventStore` while started."""

    def __init__(self, config: EventsConfig, model: FleetModel, log_events: bool = False) -> None:
        """Open the store for `config` (degraded on failure) and attach the detector to `model`."""
        self.store = EventStore(StoreSettings(config.path, config.retention, config.max_size, log_events))
        self.collector = EventsCollector(self.store)
        self.detector = TransitionDetector(model.limits, self.store.add)
        self._model = model
        self._stopping = threading.Event()
        self._thread: threading.Thread | None = None

    def start(self) -> None:
        """Listen to the model, and check its snapshots every `CHECK_INTERVAL_SECONDS`."""
        self._model.set_level_listener(self.detector.on_level_changes)
        self.store.start()
        self._thread = threading.Thread(target=self._check_loop, name="event-detector", daemon=True)
        self._thread.start()
        if self.store.available:
            log.info("recording fleet events in %s", self.store.settings.path)

    def stop(self) -> None:
        """Stop detecting, write what is queued and close the store."""
        self._stopping.set()
        self._model.set_level_listener(None)
        if self._thread is not None:
            self._thread.join(timeout=5)
        self.store.stop()

    def _check_loop(self) -> None:
        while not self._stopping.wait(CHECK_INTERVAL_SECONDS):
            try:
                self.detector.check(self._model.snapshot())
            except Exception:  # a bug here must not end event detection for good
                log.exception("event detection failed")
