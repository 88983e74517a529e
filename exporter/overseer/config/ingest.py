"""The `ingest:` section: how many worker processes share the ingest."""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from typing import Any

from overseer.config.errors import ConfigError
from overseer.config.options import Option, option

MAX_INGEST_WORKERS = 64
DEFAULT_INGEST_WORKERS_CAP = 16
OPTIONS: tuple[Option, ...] = (
    option(
        "ingest.workers",
        f"one per core, at most {DEFAULT_INGEST_WORKERS_CAP}",
        "worker processes sharing the ingest, each following the robots whose name hashes to it "
        f"(1 to {MAX_INGEST_WORKERS}); one /metrics, API and check endpoint serve them all; 1 ingests in the "
        "exporter's own process",
        metavar="N",
    ),
)
KEYS = {entry.key.partition(".")[2] for entry in OPTIONS}


def default_ingest_workers() -> int:
    """One ingest worker per core this process may run on, at most `DEFAULT_INGEST_WORKERS_CAP`."""
    try:
        cores = len(os.sched_getaffinity(0))  # honours taskset and cpusets, unlike cpu_count
    except AttributeError:  # not on Linux
        cores = os.cpu_count() or 1
    return max(1, min(cores, DEFAULT_INGEST_WORKERS_CAP))


@dataclass(frozen=True)
class IngestConfig:
    """How many worker processes share the ingest; 1 runs it in the exporter's own process."""

    workers: int = field(default_factory=default_ingest_workers)


def ingest_config(raw: dict[str, Any]) -> IngestConfig:
    """The section from its mapping."""
    value = raw.get("workers")
    if value is None:
        return IngestConfig()
    if isinstance(value, str) and value.strip().isdigit():
        value = int(value)
    if isinstance(value, bool) or not isinstance(value, int) or not 1 <= value <= MAX_INGEST_WORKERS:
        raise ConfigError(
            f"ingest.workers: expected a whole number from 1 to {MAX_INGEST_WORKERS}, got {value!r}"
        )
    return IngestConfig(value)
