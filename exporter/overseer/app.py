"""The exporter process: a fleet model (or ingest workers each holding part of it) served over HTTP."""

from __future__ import annotations

import logging
import threading
from dataclasses import dataclass, field

from prometheus_client.registry import Collector

from overseer.codec import compiled
from overseer.config import Config
from overseer.history.service import EventHistory, TransitionWatch
from overseer.model import FleetModel
from overseer.model.expiry import start_expiry
from overseer.push.icinga2_metrics import PushCollector
from overseer.push.icinga2_push import FleetSource, Icinga2Push
from overseer.serve.assembler import ExpositionAssembler
from overseer.serve.fleet_view import FleetView, ModelView, model_exposition
from overseer.serve.http import OverseerServer
from overseer.serve.web_config import load_web_config
from overseer.sources import Source, build_sources, enabled_transports
from overseer.workers.metrics import WorkerPoolCollector
from overseer.workers.pool import WorkerPool, WorkerStartError
from overseer.workers.view import PooledSnapshots, PooledView

log = logging.getLogger(__name__)


@dataclass
class Exporter:
    """The running parts of one exporter; `start` brings them up, `stop` takes them down.

    With one ingest worker the transports feed `model` in this process; with more, `pool` runs them in
    worker processes and `model` is None.
    """

    config: Config
    model: FleetModel | None = field(init=False, default=None)
    server: OverseerServer = field(init=False)
    sources: list[Source] = field(default_factory=list)
    history: EventHistory | None = None
    icinga2_push: Icinga2Push | None = None
    pool: WorkerPool | None = None
    _watch: TransitionWatch | None = None
    _stopping: threading.Event = field(default_factory=threading.Event)

    def __post_init__(self) -> None:
        config = self.config
        if config.events.enabled:
            self.history = EventHistory(config.events, config.log_format == "json")
        transports = enabled_transports(config)
        extra_collectors: list[Collector] = [] if self.history is None else [self.history.collector]
        fleet: FleetSource
        if config.ingest.workers == 1:
            model = self.model = FleetModel(config.fleet)
            self.sources = build_sources(config, model)
            if self.history is not None:
                self._watch = TransitionWatch(model, self.history.store.add)
            fleet = model
        else:
            self.pool = WorkerPool(config, None if self.history is None else self.history.store.add)
            extra_collectors.append(WorkerPoolCollector(self.pool))
            fleet = PooledSnapshots(self.pool)
        if config.icinga2 is not None:
            self.icinga2_push = Icinga2Push(config.icinga2, fleet, config.fleet.expire_after)
            extra_collectors.append(PushCollector(self.icinga2_push.stats))
        assembler = ExpositionAssembler(transports, extra_collectors, config.web.external_url)
        view: FleetView
        if self.model is not None:
            view = ModelView(self.model, model_exposition(self.model, config), assembler)
        else:
            assert self.pool is not None
            view = PooledView(self.pool, assembler)
        security = load_web_config(config.web.config_file)
        self.server = OverseerServer(config.web.host_and_port, view, security)
        self.server.events = self.history.store if self.history is not None else None

    def start(self) -> None:
        """Start the transports (or workers), the expiry timer and the HTTP server threads.

        `WorkerStartError` when a worker cannot start; everything started is stopped again.
        """
        if self.history is not None:
            self.history.start()
        if self._watch is not None:
            self._watch.start()  # before the transports, so that it sees their first messages
        for source in self.sources:
            source.start()
        if self.pool is not None:
            try:
                self.pool.start()
            except WorkerStartError:
                self.pool.stop()
                self.server.server_close()
                if self.history is not None:
                    self.history.stop()
                raise
        elif self.model is not None:
            start_expiry(self.model, self._stopping)
        threading.Thread(target=self.server.serve_forever, name="http", daemon=True).start()
        log.info("serving on %s", self.server.url)
        if compiled.enabled:
            log.info("%s", compiled.describe())
        else:
            log.warning("%s", compiled.describe())
        if self.icinga2_push is not None:
            self.icinga2_push.start()

    def stop(self) -> None:
        """Stop serving and leave the transports."""
        self._stopping.set()
        if self.pool is not None:
            self.pool.prepare_stop()
        if self.icinga2_push is not None:
            self.icinga2_push.stop()
        self.server.shutdown()
        self.server.server_close()
        for source in self.sources:
            source.stop()
        if self.pool is not None:
            self.pool.stop()
        if self._watch is not None:
            self._watch.stop()
        if self.history is not None:
            self.history.stop()
