"""Where an exporter's CPU goes, process by process: whether its ingest workers divide the cost.

The exporter's own process holds Zenoh's session, relays each worker its robots' samples and serves;
each worker ingests its share of the fleet. Adding a worker divides the ingest when each worker's CPU a
message of the fleet falls to about one worker's divided by their number, and the whole (relay and
each process's upkeep included) stays near one worker's, instead of growing with the workers.
"""

from __future__ import annotations

import contextlib
import time
from collections.abc import Mapping, Sequence

from bench.common import Row, cpu_seconds, process_tree

STEADY_CPU_A_MESSAGE = "exporter CPU a message, steady (the window's second half)"
OWN_PROCESS_A_MESSAGE = "of which the exporter's own process (Zenoh's session, the relay, serving)"
BUSIEST_WORKER_A_MESSAGE = "of which the busiest ingest worker"


class ProcessesCpu:
    """The CPU each process of `exporters` (their own and their workers) uses from its making to `stop`."""

    def __init__(self, exporters: Sequence[int]) -> None:
        """Start counting now."""
        self._exporters = frozenset(exporters)
        self._started = self._read()
        self._from = time.monotonic()
        self._used: dict[int, float] = {}
        self._seconds = 0.0

    def _read(self) -> dict[int, float]:
        readings: dict[int, float] = {}
        for exporter in self._exporters:
            for pid in process_tree(exporter):
                with contextlib.suppress(OSError, ValueError):  # a process that ended meanwhile
                    readings[pid] = cpu_seconds(pid)
        return readings

    def stop(self) -> None:
        """Stop counting; a worker started again meanwhile is left out (its time is not all in the window)."""
        ended = self._read()
        self._seconds = time.monotonic() - self._from
        self._used = {pid: ended[pid] - self._started[pid] for pid in ended.keys() & self._started.keys()}

    def rows(self, label: str, messages_a_second: float) -> list[Row]:
        """The exporters' own processes' CPU a message of the fleet, and the busiest worker's, in µs."""

        def a_message(used: float) -> float:
            return used / max(self._seconds, 1e-9) / messages_a_second * 1e6

        own = sum(used for pid, used in self._used.items() if pid in self._exporters)
        workers = [used for pid, used in self._used.items() if pid not in self._exporters]
        rows = [Row("scale", f"{label}: {OWN_PROCESS_A_MESSAGE}", a_message(own), "µs")]
        if workers:
            rows.append(Row("scale", f"{label}: {BUSIEST_WORKER_A_MESSAGE}", a_message(max(workers)), "µs"))
        return rows


def divided_rows(fleet: str, by_workers: Mapping[int, Sequence[Row]]) -> list[Row]:
    """Each worker count's steady CPU a message, and its busiest worker's, ÷ one worker's in the same run."""
    one = _figure(by_workers.get(1, ()), STEADY_CPU_A_MESSAGE)
    rows = []
    for workers, measured in sorted(by_workers.items()):
        whole = _figure(measured, STEADY_CPU_A_MESSAGE)
        busiest = _figure(measured, BUSIEST_WORKER_A_MESSAGE)
        if workers == 1 or not one or whole is None or busiest is None:
            continue
        label = f"{fleet}, {workers} workers ÷ 1 worker, same run"
        rows.append(
            Row("scale", f"{label}: exporter CPU a message, steady (multiplied: {workers})", whole / one, "x")
        )
        rows.append(
            Row("scale", f"{label}: the busiest worker's (divided: {1 / workers:.2f})", busiest / one, "x")
        )
    return rows


def _figure(rows: Sequence[Row], figure: str) -> float | None:
    """The value of the row whose figure (after its label) is `figure`, None without one."""
    return next((row.value for row in rows if row.figure.endswith(f": {figure}")), None)
