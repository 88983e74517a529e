"""The exporter process: a fleet model fed by the transports and served over HTTP."""

from __future__ import annotations

import logging
import threading
from dataclasses import dataclass, field, replace

from prometheus_client.registry import Collector, CollectorRegistry

from overseer.codec import compiled
from overseer.config import Config
from overseer.history.service import EventHistory
from overseer.model import FleetModel
from overseer.push.icinga2_metrics import PushCollector
from overseer.push.icinga2_push import Icinga2Push
from overseer.serve.exposition import FleetExposition
from overseer.serve.http import OverseerServer
from overseer.serve.message_labels import MessageLabels
from overseer.serve.metrics import FleetCollector
from overseer.serve.web_config import load_web_config
from overseer.sources import Source

log = logging.getLogger(__name__)

EXPIRY_INTERVAL_SECONDS = 1.0


@dataclass
class Exporter:
    """The running parts of one exporter; `start` brings them up, `stop` takes them down."""

    config: Config
    model: FleetModel = field(init=False)
    server: OverseerServer = field(init=False)
    sources: list[Source] = field(default_factory=list)
    history: EventHistory | None = None
    icinga2_push: Icinga2Push | None = None
    _stopping: threading.Event = field(default_factory=threading.Event)

    def __post_init__(self) -> None:
        self.model = FleetModel(self.config.fleet)
        if self.config.dds.enabled:
            from overseer.sources.dds import DdsSource

            self.sources.append(DdsSource(self.config.dds, self.model, self.config.shard))
        if self.config.ros1.enabled:
            from overseer.sources.ros1 import Ros1Source

            robots = tuple(robot for robot in self.config.ros1.robots if self.config.shard.owns(robot.name))
            self.sources.append(Ros1Source(replace(self.config.ros1, robots=robots), self.model))
        if self.config.zenoh.enabled:
            from overseer.sources.zenoh import ZenohSource

            self.sources.append(ZenohSource(self.config.zenoh, self.model, self.config.shard))
        registry = CollectorRegistry(auto_describe=True)
        transports = [source.transport for source in self.sources]
        value_keys = self.config.metrics.value_key_pattern
        metrics, external_url = self.config.metrics, self.config.web.external_url
        messages = MessageLabels(metrics.message_labels, metrics.message_label_length)
        registry.register(
            FleetCollector(self.model, value_keys, transports, messages=messages, external_url=external_url)
        )
        extra_collectors: list[Collector] = []
        if self.config.events.enabled:
            self.history = EventHistory(self.config.events, self.model, self.config.log_format == "json")
            extra_collectors.append(self.history.collector)
        if self.config.icinga2 is not None:
            self.icinga2_push = Icinga2Push(self.config.icinga2, self.model, self.config.fleet.expire_after)
            extra_collectors.append(PushCollector(self.icinga2_push.stats))
        for collector in extra_collectors:
            registry.register(collector)
        exposition = FleetExposition(
            self.model, value_keys, transports, extra_collectors, messages=messages, external_url=external_url
        )
        security = load_web_config(self.config.web.config_file)
        address = self.config.web.host_and_port
        self.server = OverseerServer(address, self.model, registry, exposition, security)
        self.server.events = self.history.store if self.history is not None else None

    def start(self) -> None:
        """Start the transports, the expiry timer and the HTTP server threads."""
        if self.history is not None:
            self.history.start()  # before the transports, so that it sees their first messages
        for source in self.sources:
            source.start()
        threading.Thread(target=self._expire_loop, name="expiry", daemon=True).start()
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
        if self.icinga2_push is not None:
            self.icinga2_push.stop()
        self.server.shutdown()
        self.server.server_close()
        for source in self.sources:
            source.stop()
        if self.history is not None:
            self.history.stop()

    def _expire_loop(self) -> None:
        while not self._stopping.wait(EXPIRY_INTERVAL_SECONDS):
            for robot in self.model.expire():
                log.info("forgot robot %s after %gs of silence", robot, self.config.fleet.expire_after)
