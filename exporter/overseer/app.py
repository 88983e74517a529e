"""The exporter process: a fleet (one model here, or ingest workers each holding part of it) and its outputs.

The fleet is read through one interface (`fleet/interface.py`); the outputs (the HTTP endpoint, the Icinga 2
push, the event history) are built here side by side, each against that interface.
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

from prometheus_client.registry import Collector

from overseer.codec import compiled
from overseer.config import Config
from overseer.config.loading import ros_settings
from overseer.fleet.interface import Fleet, FleetStart
from overseer.fleet.local import LocalFleet
from overseer.fleet.pooled import PooledFleet
from overseer.history.api import EVENTS_PATH, events_route
from overseer.history.service import EventHistory
from overseer.inventory.memory import RobotMemory
from overseer.inventory.metrics import InventoryCollector
from overseer.inventory.registry import RobotRegistry
from overseer.inventory.reload import InventoryReloader
from overseer.inventory.retirement import Retirements
from overseer.maintenance.effects import EffectsCollector, EffectStats
from overseer.maintenance.schedule import MaintenanceSchedule, open_schedule
from overseer.model import FleetModel
from overseer.push.alertmanager_silences import AlertmanagerSilences
from overseer.push.icinga2_metrics import PushCollector
from overseer.push.icinga2_push import Icinga2Push
from overseer.routes import JsonRoute
from overseer.serve.assembler import ExpositionAssembler
from overseer.serve.http import OverseerServer
from overseer.serve.lifecycle import RELOAD_PATH, reload_route
from overseer.serve.maintenance_api import MAINTENANCE_PATH, MaintenanceApi
from overseer.serve.maintenance_lines import MaintenanceLines
from overseer.serve.render_ahead import RenderAhead, RenderAheadCollector
from overseer.serve.render_timing import RenderTiming, RenderTimingCollector
from overseer.serve.retire_api import RETIREMENTS_PATH, RetireApi
from overseer.serve.web_config import load_web_config
from overseer.serve.write_access import WriteAccess
from overseer.sources import enabled_transports
from overseer.sources.ros2 import require_rclpy

if TYPE_CHECKING:
    from overseer.push.ros2_fleet import FleetDiagnosticsPublisher

log = logging.getLogger(__name__)


def open_fleet(
    config: Config, history: EventHistory | None, start: Callable[[], FleetStart]
) -> LocalFleet | PooledFleet:
    """The fleet `config` asks for: ingested in this process with one worker, by a pool with more.

    Its events go to `history`; `start` tells what it follows before it hears anything (asked again for
    each worker restarted).
    """
    if config.ingest.workers == 1:
        return LocalFleet.build(config, None if history is None else history.store.add, start())
    return PooledFleet(config, None if history is None else history.store.add_packed, start)


@dataclass
class Exporter:
    """The running parts of one exporter; `start` brings them up, `stop` takes them down."""

    config: Config
    fleet: Fleet = field(init=False)
    server: OverseerServer = field(init=False)
    maintenance: MaintenanceSchedule = field(init=False)
    inventory: InventoryReloader = field(init=False)
    memory: RobotMemory = field(init=False)
    history: EventHistory | None = None
    icinga2_push: Icinga2Push | None = None
    silences: AlertmanagerSilences | None = None
    ros2_fleet: FleetDiagnosticsPublisher | None = None
    render_ahead: RenderAhead | None = None

    def __post_init__(self) -> None:
        config = self.config
        # First: a web configuration that cannot load is a configuration error that must touch nothing.
        security = load_web_config(config.web.config_file)
        self.inventory = InventoryReloader(config.inventory.file)  # so must a bad inventory file
        if config.events.enabled:
            self.history = EventHistory(config.events, config.log_format == "json", config.fleet.max_robots)
        events = None if self.history is None else self.history.store.add
        self.memory = RobotMemory(RobotRegistry(config.events.path))
        self.fleet = open_fleet(
            config, self.history, lambda: FleetStart(self.inventory.inventory, self.memory.remembered())
        )
        self.inventory.follow_with(self.fleet.set_inventory)
        self.maintenance = open_schedule(config.maintenance, config.events.path, events)
        # Appended to /metrics after the fleet's series, in this order; the maintenance lines last.
        extra_collectors: list[Collector] = [] if self.history is None else [self.history.collector]
        if config.inventory.file is not None:
            extra_collectors.append(InventoryCollector(self.inventory))
        extra_collectors += self.fleet.collectors()
        effects: list[EffectStats] = []
        if config.icinga2 is not None:
            self.icinga2_push = Icinga2Push(
                config.icinga2, self.fleet, config.fleet.expire_after, maintenance=self.maintenance
            )
            extra_collectors.append(PushCollector(self.icinga2_push.stats))
            effects.append(self.icinga2_push.downtime_stats)
        if config.alertmanager is not None:
            self.silences = AlertmanagerSilences(config.alertmanager, self.maintenance)
            effects.append(self.silences.stats)
        if effects:
            extra_collectors.append(EffectsCollector(effects))
        if config.ros2.enabled and config.ros2.fleet_topic is not None:
            require_rclpy("ros2.enabled (--ros2)")
            from overseer.push.ros2_fleet import FleetDiagnosticsPublisher  # rclpy only with --ros2

            self.ros2_fleet = FleetDiagnosticsPublisher(config.ros2, self.fleet)
        render_timing = RenderTiming()
        extra_collectors.append(RenderTimingCollector(render_timing))
        if config.metrics.render_ahead:
            self.render_ahead = RenderAhead(self.fleet.prepare_exposition)
            extra_collectors.append(RenderAheadCollector(self.render_ahead))
        maintenance_lines = MaintenanceLines(self.maintenance, self.fleet.robot_names)
        assembler = ExpositionAssembler(
            enabled_transports(config), extra_collectors, config.web.external_url, [maintenance_lines]
        )
        access = WriteAccess(config.maintenance.writers, config.web.enable_maintenance_api)
        maintenance_api = MaintenanceApi(self.maintenance, access)
        retirements = Retirements(self.fleet, self.memory, events)
        routes: dict[str, JsonRoute] = {
            EVENTS_PATH: events_route(None if self.history is None else self.history.store),
            MAINTENANCE_PATH: maintenance_api.answer,
            RETIREMENTS_PATH: RetireApi(retirements.retire, access).answer,
            RELOAD_PATH: reload_route(self.inventory.reload, config.web.enable_lifecycle),
        }
        self.server = OverseerServer(
            config.web.host_and_port,
            self.fleet,
            assembler,
            security,
            routes=routes,
            robot_documents=maintenance_api.with_maintenance,
            on_scrape=None if self.render_ahead is None else self.render_ahead.scraped,
            render_timing=render_timing,
        )

    def reload(self) -> str | None:
        """Read the inventory file again (SIGHUP, POST /-/reload): None when it was, else why not."""
        return self.inventory.reload()

    @property
    def model(self) -> FleetModel | None:
        """The fleet model in this process (one ingest worker), None with a worker pool."""
        return self.fleet.model if isinstance(self.fleet, LocalFleet) else None

    def start(self) -> None:
        """Start the fleet (its transports or workers) and the HTTP server threads.

        `WorkerStartError` when a worker cannot start; everything started is stopped again.
        """
        if self.history is not None:
            self.history.start()
        self.maintenance.start()
        try:
            self.fleet.start()
        except Exception:
            self.server.server_close()
            self.maintenance.stop()
            if self.history is not None:
                self.history.stop()
            raise
        self.memory.start(self.fleet)
        threading.Thread(target=self.server.serve_forever, name="http", daemon=True).start()
        if self.render_ahead is not None:
            self.render_ahead.start()
        log.info("serving on %s", self.server.url)
        if self.config.dds.enabled or self.config.zenoh.enabled or self.config.ros2.enabled:
            log.info("ROS settings: %s", ros_settings(self.config))
        if compiled.enabled:
            log.info("%s", compiled.describe())
        else:
            log.warning("%s", compiled.describe())
        if self.icinga2_push is not None:
            self.icinga2_push.start()
        if self.silences is not None:
            self.silences.start()
        if self.ros2_fleet is not None:
            self.ros2_fleet.start()

    def stop(self) -> bool:
        """Stop everything in order; False when a part failed to stop (the others are stopped all the same).

        The order: no worker is restarted, the HTTP server stops answering, the pushes end, the maintenance
        schedule stops, the fleet leaves its transports (and its workers end), and the event history
        writes what is queued and closes its connection, then the maintenance windows' (the last to close
        the shared SQLite file checkpoints it: no write-ahead log is left).
        """
        steps: list[tuple[str, Callable[[], None]]] = []
        if isinstance(self.fleet, PooledFleet):
            steps.append(("ingest workers", self.fleet.prepare_stop))
        steps += [("HTTP server", self.server.shutdown), ("HTTP socket", self.server.server_close)]
        if self.render_ahead is not None:
            steps.append(("render ahead", self.render_ahead.stop))
        if self.icinga2_push is not None:
            steps.append(("Icinga 2 push", self.icinga2_push.stop))
        if self.silences is not None:
            steps.append(("Alertmanager silences", self.silences.stop))
        if self.ros2_fleet is not None:
            steps.append(("ROS 2 fleet publisher", self.ros2_fleet.stop))
        steps += [
            ("maintenance schedule", self.maintenance.stop),
            ("robots heard", self.memory.stop),  # saved while the fleet still answers
            ("fleet", self.fleet.stop),
        ]
        if self.history is not None:
            steps.append(("event history", self.history.stop))
        steps.append(("maintenance windows' database", self.maintenance.close))
        clean = True
        for what, step in steps:
            try:
                step()
            except Exception:  # the rest must still stop: the database above all
                log.exception("stopping the %s failed", what)
                clean = False
        return clean
