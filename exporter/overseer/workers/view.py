"""The fleet of every ingest worker, served as one: the exposition, the API documents, a snapshot."""

from __future__ import annotations

import time
from collections.abc import Iterator
from typing import Any

from prometheus_client.metrics_core import Metric
from prometheus_client.registry import Collector

from overseer.model import FleetSnapshot
from overseer.serve.api import ComponentQuery
from overseer.serve.exposition import ExpositionAssembler
from overseer.workers.merge import (
    merge_components_documents,
    merge_families,
    merge_robots_documents,
    merge_snapshots,
)
from overseer.workers.pool import WorkerPool


class PooledView:
    """Asks every worker (or the one owning a robot) and joins the answers."""

    def __init__(self, pool: WorkerPool, assembler: ExpositionAssembler) -> None:
        """Serve `pool`'s fleet, assembling its exposition with `assembler` (which adds the extras)."""
        self.pool = pool
        self._assembler = assembler
        self._owners = [pool.config.shard.for_worker(index, pool.count) for index in range(pool.count)]

    def metrics_text(self) -> bytes:
        """Every worker's series under one header per family, counters added up."""
        return self._assembler.assemble(self.pool.ask_all("part"))

    def robots_document(self) -> dict[str, Any]:
        """Every worker's robots, by name."""
        return merge_robots_documents(self.pool.ask_all("robots"), time.time())

    def robot_document(self, name: str) -> dict[str, Any] | None:
        """The robot from the one worker that follows it, or None."""
        for index, owner in enumerate(self._owners):
            if owner.owns(name):
                answer = self.pool.ask(index, "robot", name)
                return None if answer is None else answer[0]
        return None

    def components_document(self, query: ComponentQuery) -> dict[str, Any]:
        """The fleet's first matches among every worker's first matches."""
        return merge_components_documents(self.pool.ask_all("components", query), query.limit, time.time())


class PooledSnapshots:
    """Snapshots of the whole fleet, copied from every worker: for the Icinga 2 push, not for every scrape."""

    def __init__(self, pool: WorkerPool) -> None:
        """Take snapshots of `pool`'s workers."""
        self._pool = pool

    def snapshot(self) -> FleetSnapshot:
        """One snapshot of the whole fleet now."""
        return merge_snapshots(self._pool.ask_all("snapshot"), self._pool.config.fleet, time.time())


class PooledCollector(Collector):
    """The fleet's metric families for OpenMetrics scrapes, joined from every worker's."""

    def __init__(self, pool: WorkerPool) -> None:
        """Collect from `pool`'s workers."""
        self._pool = pool

    def collect(self) -> Iterator[Metric]:
        """Every worker's families, merged."""
        yield from merge_families(self._pool.ask_all("families"))
