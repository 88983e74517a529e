"""Where an exporter's CPU goes, process by process: whether its ingest workers divide the cost.

The exporter's own process serves, and over Zenoh holds the one session and relays each worker its
robots' samples; each worker ingests its share of the fleet (over DDS, with a participant of its own).
Adding a worker divides the ingest when the whole (the relay and each process's upkeep included) stays
near one worker's instead of growing with the workers, and each worker's CPU a message of the fleet is
at most one worker's divided by their number: less, since one worker's figure also holds the serving
and, over Zenoh, the session, which stay in the exporter's own process.
"""

from __future__ import annotations

import contextlib
import time
from collections.abc import Sequence
from dataclasses import dataclass

from bench.common import Row, cpu_seconds, process_tree

STEADY_CPU_A_MESSAGE = "exporter CPU a message, steady (the window's second half)"
OWN_PROCESS_A_MESSAGE = "of which the exporter's own process (serving; over Zenoh, the session and its relay)"
BUSIEST_WORKER_A_MESSAGE = "of which the busiest ingest worker"
WORKERS_LEFT_OUT = (
    "ingest workers started or ended in the window (not told apart; an ended one not in the whole)"
)


@dataclass(frozen=True)
class CpuSplit:
    """CPU seconds used over `seconds`: in all, by the exporters' own processes, by each worker."""

    seconds: float
    whole: float
    own: float
    workers: tuple[float, ...]
    left_out: int  # worker processes that started or ended in the window: not all their time is in it

    def rows(self, label: str, messages_a_second: float) -> list[Row]:
        """The own processes' and the busiest worker's CPU a message of the fleet (µs); none if no worker."""
        if not self.workers and not self.left_out:
            return []  # one worker ingests in the exporter's own process: the whole is its

        def a_message(used: float) -> float:
            return used / self.seconds / messages_a_second * 1e6

        rows = [Row("scale", f"{label}: {OWN_PROCESS_A_MESSAGE}", a_message(self.own), "µs")]
        if self.workers:
            rows.append(
                Row("scale", f"{label}: {BUSIEST_WORKER_A_MESSAGE}", a_message(max(self.workers)), "µs")
            )
        if self.left_out:
            rows.append(Row("scale", f"{label}: {WORKERS_LEFT_OUT}", self.left_out, "processes"))
        return rows


class ProcessesCpu:
    """Reads the CPU of each process of `exporters` (their own, their workers') now and at `stop`."""

    def __init__(self, exporters: Sequence[int]) -> None:
        """Start counting now."""
        self._exporters = frozenset(exporters)
        self._from = time.monotonic()
        self._started = self._read()

    def _read(self) -> dict[int, float]:
        readings: dict[int, float] = {}
        for exporter in self._exporters:
            for pid in process_tree(exporter):
                with contextlib.suppress(OSError, ValueError):  # a process that ended meanwhile
                    readings[pid] = cpu_seconds(pid)
        return readings

    def stop(self) -> CpuSplit:
        """What each process used since the start.

        A process started meanwhile counts whole in `whole`; one that ended meanwhile is missing from it
        (what it used before it ended cannot be read). Neither is told apart as a worker.
        """
        ended = self._read()
        seconds = max(time.monotonic() - self._from, 1e-9)
        kept = ended.keys() & self._started.keys()
        used = {pid: ended[pid] - self._started[pid] for pid in kept}
        started = sum(ended[pid] for pid in ended.keys() - kept)
        left_out = len((ended.keys() ^ self._started.keys()) - self._exporters)
        own = sum(cpu for pid, cpu in used.items() if pid in self._exporters)
        workers = tuple(cpu for pid, cpu in used.items() if pid not in self._exporters)
        return CpuSplit(seconds, sum(used.values()) + started, own, workers, left_out)


def compared_with_one_worker(fleet: str, setup: str, runs: Sequence[tuple[int, Sequence[Row]]]) -> list[Row]:
    """Each run of several workers ÷ the one-worker run nearest it in the invocation: whole, busiest.

    `fleet` and `setup` are the runs' label before and after their worker count.
    """
    ones = [index for index, (workers, _) in enumerate(runs) if workers == 1]
    rows: list[Row] = []
    for index, (workers, measured) in enumerate(runs):
        if workers == 1 or not ones:
            continue
        one = runs[min(ones, key=lambda one_index: abs(one_index - index))][1]
        rows += _compared(
            f"{fleet}, {workers} workers ÷ 1 worker{setup}, same invocation", workers, measured, one
        )
    return rows


def _compared(label: str, workers: int, measured: Sequence[Row], one_worker: Sequence[Row]) -> list[Row]:
    one = _figure(one_worker, STEADY_CPU_A_MESSAGE)
    whole = _figure(measured, STEADY_CPU_A_MESSAGE)
    busiest = _figure(measured, BUSIEST_WORKER_A_MESSAGE)
    if not one or whole is None or busiest is None or _figure(measured, WORKERS_LEFT_OUT):
        return []  # nothing to compare, or a worker that restarted: the parts are not all there
    return [
        Row(
            "scale",
            f"{label}: exporter CPU a message, steady",
            whole / one,
            "x",
            f"~ 1 divided, ~ {workers} multiplied",
        ),
        Row(
            "scale",
            f"{label}: the busiest worker's",
            busiest / one,
            "x",
            f"<= {1 / workers:.2f} divided, ~ 1 multiplied",
        ),
    ]


def _figure(rows: Sequence[Row], figure: str) -> float | None:
    """The value of the row whose figure (after its label) is `figure`, None without one."""
    return next((row.value for row in rows if row.figure.endswith(f": {figure}")), None)
