"""The fleet held by one model in this process: the exporter's own with one ingest worker, or a worker's.

`LocalFleet` is the one builder of "model + sources + level listener + expiry + renderer": the exporter
builds one when it ingests itself, and every ingest worker builds one for the robots it follows.
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Collection, Mapping
from typing import Any

from prometheus_client.registry import Collector

from overseer.config import Config
from overseer.fleet.documents import (
    ComponentQuery,
    RobotQuery,
    components_document,
    robot_document,
    robots_document,
)
from overseer.fleet.exposition import ExpositionPart, FleetExposition
from overseer.fleet.interface import FleetStart
from overseer.fleet.level_digests import Signatures
from overseer.fleet.message_labels import MessageLabels
from overseer.model import FleetModel, FleetSnapshot, Inventory, RememberedRobot
from overseer.model.events import EventSink
from overseer.model.expiry import start_expiry
from overseer.model.robot_cap import RobotCap
from overseer.model.shard import Shard
from overseer.model.transitions import TransitionDetector
from overseer.sources import Source, build_sources
from overseer.sources.zenoh.relay_items import RelayedFeed

log = logging.getLogger(__name__)

CHECK_INTERVAL_SECONDS = 1.0


class LocalFleet:
    """A fleet model, the transports that feed it, the watch of its transitions and its renderer."""

    def __init__(
        self,
        model: FleetModel,
        sources: list[Source],
        exposition: FleetExposition,
        events: EventSink | None = None,
        start: FleetStart | None = None,
        shard: Shard | None = None,
    ) -> None:
        """Serve `model`, fed by `sources`, rendered by `exposition`; `events` receives its transitions.

        `start` is what it follows from the start; of it, and of every inventory, only the robots `shard`
        owns.
        """
        self.model = model
        self.sources = sources
        self.exposition = exposition
        self._watch = None if events is None else TransitionWatch(model, events)
        self._stopping = threading.Event()
        self._start = start or FleetStart()
        self._shard = shard or Shard()
        self._signatures = Signatures()

    @classmethod
    def build(
        cls,
        config: Config,
        events: EventSink | None = None,
        start: FleetStart | None = None,
        relayed: Mapping[str, RelayedFeed] | None = None,
        robot_cap: RobotCap | None = None,
    ) -> LocalFleet:
        """The fleet `config` describes: its model, the transports it enables, its renderer; not started.

        `events`, when given, receives the model's transitions (level changes as they are applied, and
        what time decides, checked every second); `start` says what it follows before it hears anything;
        `relayed` what an ingest worker reads from the exporter's relays, by transport, and `robot_cap` its
        count of robots against the whole fleet's cap.
        """
        model = FleetModel(config.fleet, robot_cap=robot_cap)
        metrics = config.metrics
        messages = MessageLabels(metrics.message_labels, metrics.message_label_length)
        exposition = FleetExposition(
            model, metrics.value_key_pattern, messages=messages, level_changes=metrics.level_changes
        )
        sources = build_sources(config, model, relayed)
        return cls(model, sources, exposition, events, start, config.shard)

    def start(self) -> None:
        """Follow the robots listed and remembered, watch transitions, start the transports, expire."""
        owns = self._shard.owns
        self.model.set_inventory(self._start.inventory, owns)
        self.model.remember(robot for robot in self._start.remembered if owns(robot.name))
        if self._watch is not None:
            self._watch.start()  # before the transports, so that it sees their first messages
        for source in self.sources:
            source.start()
        start_expiry(self.model, self._stopping)

    def stop(self) -> None:
        """Leave the transports and stop the timers."""
        self._stopping.set()
        for source in self.sources:
            source.stop()
        if self._watch is not None:
            self._watch.stop()

    def robot_digests(self) -> dict[str, int | None]:
        """Every robot → its digest (None while awaiting), kept from the last call where nothing changed."""
        return self._signatures.digests(self.model.snapshot())

    def robots_snapshot(self, names: Collection[str]) -> FleetSnapshot:
        """The model now, with only the robots named."""
        return self.model.robots_snapshot(names)

    def exposition_parts(self) -> list[ExpositionPart]:
        """The model's rendered series and counters."""
        return [self.exposition.render_part()]

    def prepare_exposition(self) -> None:
        """Render what changed now; the next scrape copies it."""
        self.exposition.render_part()

    def robots_document(self, query: RobotQuery | None = None) -> dict[str, Any]:
        """Every robot's summary, or those `query` selects."""
        return robots_document(self.model.snapshot(), query)

    def robot_names(self) -> list[str]:
        """The names of the robots followed now."""
        return [robot.name for robot in self.model.snapshot().robots]

    def robot_document(self, name: str) -> dict[str, Any] | None:
        """One robot with every component, or None."""
        snapshot = self.model.robots_snapshot((name,))
        robot = snapshot.find(name)
        return None if robot is None else robot_document(snapshot, robot)

    def components_document(self, query: ComponentQuery) -> dict[str, Any]:
        """The components matching `query`."""
        return components_document(self.model.snapshot(), query)

    def collectors(self) -> list[Collector]:
        """None: one model in this process has no metrics of its own beyond its series."""
        return []

    def set_inventory(self, inventory: Inventory) -> None:
        """Follow the robots of `inventory` this fleet's shard owns."""
        self.model.set_inventory(inventory, self._shard.owns)

    def retire(self, robot: str) -> str:
        """Forget a robot that is down and not listed (see `FleetModel.retire`)."""
        return self.model.retire(robot)

    def heard(self, with_components: bool = False) -> list[RememberedRobot]:
        """Every robot heard and when it was last heard (and what it reported, `with_components`)."""
        return self.model.heard(with_components)


class TransitionWatch:
    """Detects a model's transitions while started: its level listener, and a check every second."""

    def __init__(self, model: FleetModel, sink: EventSink) -> None:
        """Watch `model`, sending its events to `sink`."""
        self.detector = TransitionDetector(model.limits, sink)
        self._model = model
        self._stopping = threading.Event()
        self._thread: threading.Thread | None = None

    def start(self) -> None:
        """Listen to the model, and check its snapshots now and every `CHECK_INTERVAL_SECONDS`."""
        self._model.set_level_listener(self.detector.on_level_changes)
        # The first look, before any transport delivers: the robots listed and remembered are seen as
        # they were, so a remembered robot that speaks at once continues its run rather than "come up".
        self.detector.check(self._model.told_snapshot())
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
                self.detector.check(self._model.told_snapshot())
            except Exception:  # a bug here must not end event detection for good
                log.exception("event detection failed")
