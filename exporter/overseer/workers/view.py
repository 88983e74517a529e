"""The fleet of every ingest worker, served as one: the exposition, the API documents, a snapshot."""

from __future__ import annotations

import time
from dataclasses import replace
from typing import Any

from overseer.model import FleetSnapshot
from overseer.serve.api import ComponentQuery
from overseer.serve.assembler import ExpositionAssembler
from overseer.serve.exposition import ExpositionPart
from overseer.serve.exposition_formats import ExpositionFormat
from overseer.workers.merge import (
    CounterCarry,
    counters_part,
    merge_components_documents,
    merge_robots_documents,
    merge_snapshots,
    part_counters,
)
from overseer.workers.pool import WorkerPool, WorkersUnavailable

SNAPSHOT_REUSE_SECONDS = 1.0


class PooledView:
    """Asks every worker (or the one owning a robot) and joins the answers."""

    def __init__(self, pool: WorkerPool, assembler: ExpositionAssembler) -> None:
        """Serve `pool`'s fleet, assembling its exposition with `assembler` (which adds the extras)."""
        self.pool = pool
        self._assembler = assembler
        self._owners = [pool.config.shard.for_worker(index, pool.count) for index in range(pool.count)]
        self._counters = CounterCarry(pool.count)

    def metrics(self, fmt: ExpositionFormat) -> bytes:
        """Every worker's series under one header per family, counters added up and never going back."""
        answers = self.pool.ask_all("part")
        totals = self._counters.totals((a.worker, a.generation, part_counters(a.value)) for a in answers)
        parts = [_without_counters(answer.value) for answer in answers]
        return self._assembler.assemble([*parts, counters_part(totals)], fmt)

    def robots_document(self) -> dict[str, Any]:
        """Every worker's robots, by name."""
        return merge_robots_documents([a.value for a in self.pool.ask_all("robots")], time.time())

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


class PooledSnapshots:
    """Snapshots of the whole fleet, copied from every worker: for the Icinga 2 push, not for every scrape."""

    def __init__(self, pool: WorkerPool) -> None:
        """Take snapshots of `pool`'s workers."""
        self._pool = pool
        self._last: FleetSnapshot | None = None

    def snapshot(self) -> FleetSnapshot:
        """One snapshot of the whole fleet, at most `SNAPSHOT_REUSE_SECONDS` old.

        `WorkersUnavailable` when a worker cannot answer: a snapshot without its robots would tell the push
        they are gone, and it would delete their hosts in Icinga 2.
        """
        last = self._last
        if last is not None and time.time() - last.taken_at < SNAPSHOT_REUSE_SECONDS:
            return last
        answers = self._pool.ask_every("snapshot")
        self._last = merge_snapshots([a.value for a in answers], self._pool.config.fleet, time.time())
        return self._last


def _without_counters(part: ExpositionPart) -> ExpositionPart:
    return replace(part, message_counts={}, dropped_statuses={}, truncated_strings=0, source_errors={})
