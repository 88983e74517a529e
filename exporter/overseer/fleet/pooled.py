"""The fleet held by a pool of ingest workers, served as one: snapshots, series, documents.

Each worker follows its own robots (`workers/`); every answer here is joined from the workers' answers
(`workers/merge.py`), so the outputs read one fleet, each robot exactly once and counters added up.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Collection
from dataclasses import replace
from typing import Any

from prometheus_client.registry import Collector

from overseer.config import Config
from overseer.fleet.documents import ComponentQuery, RobotQuery
from overseer.fleet.exposition import ExpositionPart
from overseer.fleet.interface import FleetStart
from overseer.fleet.workers.merge import (
    CounterCarry,
    counters_part,
    merge_components_documents,
    merge_robots_documents,
    merge_snapshots,
    part_counters,
)
from overseer.fleet.workers.metrics import WorkerPoolCollector
from overseer.fleet.workers.pool import Relay, WorkerPool, WorkerStartError, WorkersUnavailable
from overseer.model import FleetSnapshot, Inventory, RememberedRobot
from overseer.model.events import PackedRowSink

SNAPSHOT_REUSE_SECONDS = 1.0


class PooledFleet:
    """`config.ingest.workers` workers asked together (or the one owning a robot), their answers joined.

    `events`, when given, receives every worker's transitions.
    """

    def __init__(
        self,
        config: Config,
        events: PackedRowSink | None = None,
        start: Callable[[], FleetStart] | None = None,
    ) -> None:
        """Prepare the pool; no worker runs until `start`. `start` says what a worker follows at first.

        The exporter's own DDS participants and Zenoh session relay each worker its robots' samples
        (`DdsRelay`, `ZenohRelay`).
        """
        count = config.ingest.workers
        self.relays: dict[str, Relay] = {}
        if config.dds.enabled:  # the middleware loads only when enabled
            from overseer.sources.dds.relay import DdsRelay

            self.relays["dds"] = DdsRelay(config.dds, config.shard, count, config.robot_namespace_depth)
        if config.zenoh.enabled:
            from overseer.sources.zenoh.relay import ZenohRelay

            self.relays["zenoh"] = ZenohRelay(config.zenoh, config.shard, count, config.robot_namespace_depth)
        self.pool = WorkerPool(config, events, start, self.relays)
        self._owners = [config.shard.for_worker(index, self.pool.count) for index in range(self.pool.count)]
        self._counters = CounterCarry(self.pool.count)
        self._last_digests: tuple[float, dict[str, int | None]] | None = None

    def start(self) -> None:
        """Start every worker, then the relays; `WorkerStartError` (and nothing left running) on failure."""
        starting = ""  # the relay starting, while one does
        try:
            self.pool.start()
            for transport, relay in self.relays.items():
                starting = transport
                relay.start()
        except Exception as error:
            self.stop()  # every relay (the one that failed too: what it joined), then the workers
            if not starting:
                raise
            # A DDS configuration Cyclone refuses, say: the exporter's own participant could not join.
            raise WorkerStartError(f"{starting} could not start: {type(error).__name__}: {error}") from error

    def prepare_stop(self) -> None:
        """Restart no worker from now on: the exporter is stopping (and may see its workers end first)."""
        self.pool.prepare_stop()

    def stop(self) -> None:
        """Stop every worker, after the DDS participants and Zenoh session that relay them their samples."""
        try:
            for relay in self.relays.values():
                relay.stop()
        finally:
            self.pool.stop()

    def robot_digests(self) -> dict[str, int | None]:
        """Every worker's robots and digests, at most `SNAPSHOT_REUSE_SECONDS` old.

        `WorkersUnavailable` when a worker cannot answer: digests without its robots would tell the
        Icinga 2 push that they are gone, and it would delete their hosts. A few hundred kilobytes at
        10,000 robots, where their snapshot is tens of megabytes to pickle.
        """
        last = self._last_digests
        if last is not None and time.monotonic() - last[0] < SNAPSHOT_REUSE_SECONDS:
            return last[1]
        taken_at = time.monotonic()
        digests: dict[str, int | None] = {}
        for answer in self.pool.ask_every("digests"):
            digests.update(answer.value)
        self._last_digests = (taken_at, digests)
        return digests

    def robots_snapshot(self, names: Collection[str]) -> FleetSnapshot:
        """The named robots from the workers that follow them, in one snapshot; raises as `robot_digests`."""
        wanted = frozenset(names)
        answers = self.pool.ask_every("snapshot_of", wanted) if wanted else []
        parts = [answer.value for answer in answers]
        return merge_snapshots(parts, self.pool.config.fleet, time.monotonic(), time.time())

    def exposition_parts(self) -> list[ExpositionPart]:
        """Every worker's series, and the counters added up, never going back when a worker restarts."""
        answers = self.pool.ask_all("part")
        totals = self._counters.totals((a.worker, a.generation, part_counters(a.value)) for a in answers)
        return [*(_without_counters(answer.value) for answer in answers), counters_part(totals)]

    def prepare_exposition(self) -> None:
        """Every worker renders what changed now, at once; `WorkersUnavailable` when one could not."""
        self.pool.ask_every("prepare")

    def robots_document(self, query: RobotQuery | None = None) -> dict[str, Any]:
        """Every worker's robots (those `query` selects), by name."""
        return merge_robots_documents([a.value for a in self.pool.ask_all("robots", query)], time.time())

    def robot_names(self) -> list[str]:
        """Every worker's robots' names (none of a worker that does not answer)."""
        return [name for answer in self.pool.ask_all("names") for name in answer.value]

    def robot_document(self, name: str) -> dict[str, Any] | None:
        """The robot from the one worker that follows it, or None."""
        for index, owner in enumerate(self._owners):
            if owner.owns(name):
                answer = self.pool.ask(index, "robot", name)
                if answer is None:
                    raise WorkersUnavailable(f"ingest worker {index}, which follows {name!r}, did not answer")
                return answer[0]  # type: ignore[no-any-return]
        return None

    def components_document(self, query: ComponentQuery) -> dict[str, Any]:
        """The fleet's first matches among every worker's first matches."""
        return merge_components_documents(
            [a.value for a in self.pool.ask_all("components", query)], query.limit, time.time()
        )

    def collectors(self) -> list[Collector]:
        """How the workers fare: how many, which are up, how often each was restarted."""
        return [WorkerPoolCollector(self.pool)]

    def set_inventory(self, inventory: Inventory) -> None:
        """Every worker follows its robots of `inventory` (a worker restarting gets it as it starts)."""
        self.pool.ask_all("inventory", inventory)

    def retire(self, robot: str) -> str:
        """The worker that follows `robot` forgets it, if it is down and not listed."""
        for index, owner in enumerate(self._owners):
            if owner.owns(robot):
                answer = self.pool.ask(index, "retire", robot)
                if answer is None:
                    raise WorkersUnavailable(
                        f"ingest worker {index}, which follows {robot!r}, did not answer"
                    )
                return str(answer[0])
        return "unknown"

    def heard(self, with_components: bool = False) -> list[RememberedRobot]:
        """Every worker's robots heard; `WorkersUnavailable` rather than a list missing a worker's."""
        return [robot for answer in self.pool.ask_every("heard", with_components) for robot in answer.value]


def _without_counters(part: ExpositionPart) -> ExpositionPart:
    return replace(
        part, message_counts={}, dropped_statuses={}, truncated_strings=0, source_errors={}, forgotten={}
    )
