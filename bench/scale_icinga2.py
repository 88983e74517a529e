"""bench_scale's Icinga 2: a real daemon the exporter pushes the fleet to, and what it received meanwhile.

The exporter's ApiUser may deploy config packages (as `docs/nagios-icinga.md` advises for large fleets),
so a fleet first heard is registered in stages; its results are pushed again every `interval`.
"""

from __future__ import annotations

import re
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import NamedTuple

from bench.bench_icinga2 import icinga2_cpu
from bench.common import Row, series_total
from testbed.icinga2 import (
    PUSH_BULK_USER,
    Icinga2,
    push_api_user,
    push_bulk_api_user,
    push_config,
    running_icinga2,
)

EXPORTER_ID = "scale"
RECEIVED_TARGET = 0.95  # of the results due a minute: each object once an interval, a few on their way


class PushMark(NamedTuple):
    """Where a measured stretch of the push begins."""

    at: float  # monotonic
    icinga_cpu: float  # seconds, the daemon's own


class Icinga2Receiving:
    """A running Icinga 2 the exporter pushes to, with the exporter option that makes it push there."""

    def __init__(self, daemon: Icinga2, config: Path, interval: float) -> None:
        """Read `daemon`, pushed to every `interval` per the exporter configuration file `config`."""
        self.daemon = daemon
        self.option = f"--config.file={config}"
        self.interval = interval

    def mark(self) -> PushMark:
        """Now, to measure from."""
        return PushMark(time.monotonic(), icinga2_cpu(self.daemon)[0])

    def rows(self, since: PushMark, metrics: str) -> list[Row]:
        """What Icinga received since `since` and what it cost it; `metrics` is the exporter's /metrics."""
        cpu = (icinga2_cpu(self.daemon)[0] - since.icinga_cpu) / (time.monotonic() - since.at)
        status = self.daemon.api("GET", "/v1/status/CIB", {})["results"][0]["status"]
        objects = sum(
            status[f"num_{kind}_{state}"]
            for kind, states in (("hosts", HOST_STATES), ("services", SERVICE_STATES))
            for state in states
        )
        received = status["passive_host_checks_1min"] + status["passive_service_checks_1min"]
        due = objects * 60 / self.interval
        failures = failed_requests(metrics)
        failed = sum(failures.values())
        stages = series_total(metrics, r'overseer_icinga2_package_stages_total\{result="ok"\}')
        pending = series_total(metrics, "overseer_icinga2_pending_results")
        every = f"every {self.interval:g} s"
        return [
            Row("scale", f"Icinga 2 push {every}: hosts and services registered", objects, "objects"),
            Row("scale", f"Icinga 2 push {every}: results received, the last minute", received, "/min"),
            Row(
                "scale",
                f"Icinga 2 push {every}: of those due a minute (every object once an interval)",
                received / max(due, 1),
                "",
                f">= {RECEIVED_TARGET}",
                received >= RECEIVED_TARGET * due,
            ),
            Row("scale", f"Icinga 2 push {every}: results waiting in the exporter", pending, "results"),
            Row(
                "scale",
                f"Icinga 2 push {every}: requests failed",
                failed,
                "requests" + "".join(f", {reason}: {count:g}" for reason, count in sorted(failures.items())),
                "0",
                failed == 0,
            ),
            Row(
                "scale",
                f"Icinga 2 push {every}: config package stages (registering robots and their groups)",
                stages,
                "stages",
            ),
            Row("scale", f"Icinga 2 push {every}: Icinga 2's CPU", cpu * 100, "% of a core"),
        ]


def failed_requests(metrics: str) -> dict[str, float]:
    """The push's failed requests in the exporter's `/metrics`, by reason (`timeout`, `connection`...)."""
    pattern = r'^overseer_icinga2_pushes_total\{result="([a-z_0-9]+)"\} (\S+)$'
    counts = re.findall(pattern, metrics, re.MULTILINE)
    return {reason: float(count) for reason, count in counts if reason != "ok" and float(count)}


HOST_STATES = ("up", "down", "unreachable", "pending")
SERVICE_STATES = ("ok", "warning", "critical", "unknown", "pending")


@contextmanager
def icinga2_receiving(directory: Path, interval: float | None) -> Iterator[Icinga2Receiving | None]:
    """Icinga 2 running for the exporter to push to every `interval` s (None: no Icinga, no push)."""
    if interval is None:
        yield None
        return
    with running_icinga2(directory / "icinga2", push_api_user() + push_bulk_api_user()) as daemon:
        config = push_config(directory, daemon, EXPORTER_ID, f"{interval:g}s", username=PUSH_BULK_USER)
        yield Icinga2Receiving(daemon, config, interval)
