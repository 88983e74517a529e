"""What every benchmark shares: result rows, their table, and process CPU and memory readings."""

from __future__ import annotations

import contextlib
import json
import math
import os
import re
import sys
import threading
import time
from collections.abc import Callable, Iterable, Iterator, Sequence
from dataclasses import asdict, dataclass
from typing import TextIO, TypeVar

from testbed.paths import REPO

ROW_PREFIX = "BENCH-ROW "
_TICKS = os.sysconf("SC_CLK_TCK")
_PAGE = os.sysconf("SC_PAGE_SIZE")
_Number = TypeVar("_Number", int, float)


@dataclass(frozen=True)
class Row:
    """One measured figure, with the target it is held to (empty when it has none)."""

    benchmark: str
    figure: str
    value: float
    unit: str
    target: str = ""
    met: bool | None = None


def emit(rows: Iterable[Row]) -> None:
    """Print rows for `python -m bench` to collect, and as a table for a person running one benchmark."""
    rows = list(rows)
    for row in rows:
        print(ROW_PREFIX + json.dumps(asdict(row)), flush=True)
    print_table(rows, file=sys.stderr)


def print_table(rows: Iterable[Row], file: TextIO | None = None) -> None:
    """A fixed-width table of rows."""
    out = file or sys.stdout
    header = ("benchmark", "figure", "value", "unit", "target", "met")
    lines = [header] + [
        (
            r.benchmark,
            r.figure,
            _number(r.value),
            r.unit,
            r.target,
            {True: "yes", False: "NO", None: ""}[r.met],
        )
        for r in rows
    ]
    widths = [max(len(line[i]) for line in lines) for i in range(len(header))]
    for index, line in enumerate(lines):
        print(
            "  ".join(cell.ljust(width) for cell, width in zip(line, widths, strict=True)).rstrip(), file=out
        )
        if index == 0:
            print("  ".join("-" * width for width in widths), file=out)


def _number(value: float) -> str:
    if not math.isfinite(value):
        return str(value)  # a figure the run could not measure (a first look that never ended)
    if value == int(value) and abs(value) < 1e15:
        return f"{int(value):,}"
    return f"{value:,.3g}" if abs(value) < 10 else f"{value:,.1f}"


def series_total(text: str, pattern: str) -> float:
    """The sum of the samples in exposition `text` whose name and labels match `pattern` whole."""
    return sum(float(value) for value in re.findall(rf"^{pattern} (\S+)$", text, re.MULTILINE))


def repo_on_path() -> dict[str, str]:
    """The environment a `python -m bench.…` child needs to import this tree (the caller's path kept)."""
    return {"PYTHONPATH": os.pathsep.join(p for p in (str(REPO), os.environ.get("PYTHONPATH", "")) if p)}


def cpu_seconds(pid: int) -> float:
    """User plus system CPU time a process has used."""
    with open(f"/proc/{pid}/stat", encoding="ascii") as stat:
        fields = stat.read().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / _TICKS


def resident_bytes(pid: int | None = None) -> int:
    """Resident memory of a process (this one by default)."""
    with open(f"/proc/{pid or 'self'}/statm", encoding="ascii") as statm:
        return int(statm.read().split()[1]) * _PAGE


def interleaved_rates(workloads: dict[str, Callable[[], int]], rounds: int = 5) -> dict[str, float]:
    """Items per CPU second of each workload's fastest run (each returns its item count).

    The workloads take turns, round after round, so that a neighbour loading this shared machine
    slows all of them alike, and CPU time leaves out the time this process was not running.
    """
    best = dict.fromkeys(workloads, 0.0)
    for _ in range(rounds):
        for name, work in workloads.items():
            started = time.process_time()
            items = work()
            best[name] = max(best[name], items / (time.process_time() - started))
    return best


def process_tree(pid: int) -> list[int]:
    """`pid` and every process descending from it (an exporter and its ingest workers)."""
    children: dict[int, list[int]] = {}
    for entry in os.listdir("/proc"):
        if not entry.isdigit():
            continue
        try:
            with open(f"/proc/{entry}/stat", encoding="ascii", errors="replace") as stat:
                parent = int(stat.read().rsplit(")", 1)[1].split()[1])
        except (OSError, ValueError):
            continue
        children.setdefault(parent, []).append(int(entry))
    tree, pending = [], [pid]
    while pending:
        current = pending.pop()
        tree.append(current)
        pending.extend(children.get(current, ()))
    return tree


def tree_cpu_seconds(pid: int) -> float:
    """CPU time used so far by `pid` and its live descendants."""
    return _summed_over_tree(pid, cpu_seconds, 0.0)


def tree_resident_bytes(pid: int) -> int:
    """Resident memory of `pid` and its live descendants, summed."""
    return _summed_over_tree(pid, resident_bytes, 0)


def tree_proportional_bytes(pid: int) -> int:
    """Proportional memory (PSS) of `pid` and its live descendants, summed: shared pages counted once."""
    return _summed_over_tree(pid, proportional_bytes, 0)


def proportional_bytes(pid: int) -> int:
    """Proportional memory (PSS) of a process: each page it shares divided among its sharers."""
    with open(f"/proc/{pid}/smaps_rollup", encoding="ascii") as rollup:
        return next((int(line.split()[1]) for line in rollup if line.startswith("Pss:")), 0) * 1024


def _summed_over_tree(pid: int, measure: Callable[[int], _Number], zero: _Number) -> _Number:
    """`measure` of `pid` and of each of its live descendants, summed."""
    total = zero
    for member in process_tree(pid):
        with contextlib.suppress(OSError, ValueError):  # it ended meanwhile
            total += measure(member)
    return total


def forest(measure: Callable[[int], _Number], pids: Sequence[int]) -> _Number:
    """`measure` (of a process and its descendants) summed over `pids`, at least one."""
    return sum((measure(pid) for pid in pids[1:]), measure(pids[0]))


def highest_tree_resident(pids: Iterable[int], until: float, every: float = 1.0) -> int:
    """The most resident memory of `pids` and their descendants together, read every `every` s to `until`."""
    pids = tuple(pids)
    highest = 0
    while True:
        highest = max(highest, forest(tree_resident_bytes, pids))
        left = until - time.monotonic()
        if left <= 0:
            return highest
        time.sleep(min(every, left))


@contextlib.contextmanager
def busy_interpreter() -> Iterator[None]:
    """A thread running pure Python that never waits, as the ingest does while samples queue up.

    Whatever lets go of the interpreter lock meanwhile (a socket send, an SQLite statement) waits up to
    the switch interval (5 ms) to take it back: what is measured beside it counts those waits.
    """
    stop = threading.Event()

    def spin() -> None:
        while not stop.is_set():
            sum(range(100))

    spinner = threading.Thread(target=spin, name="busy-interpreter", daemon=True)
    spinner.start()
    try:
        yield
    finally:
        stop.set()
        spinner.join()
