"""Event history: what detecting and storing transitions costs at 1,000 robots x 50 components at 1 Hz.

Two fleet models get the same traffic, second by fleet second, taking turns: every robot's battery
voltage changes every second (applied as the ingest applies it, by `apply_changes`), and a realistic
share of levels change. One model has nothing attached; the other has the event history's level hook,
the snapshot check every fleet second and a store on a real SQLite file, flushed in this thread at the
end of each second so that its CPU is counted here. The difference in CPU time between the two, per
fleet second, is what the event history costs. The clock is the fleets' own, so a fleet second takes
only the CPU it needs, and robots that stop publishing really go down and come back.

Realistic: 50 level changes a second in the fleet (one component in a thousand), ten robots silent for
15 s. Worst case: every component of every robot changes level every second (50,000 events a second).
"""

from __future__ import annotations

import contextlib
import functools
import gc
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from bench.common import Row, busy_interpreter, emit
from overseer.history.query import EventQuery
from overseer.history.store import EventStore, StoreSettings, insert_statement
from overseer.levels import Level
from overseer.messages import DiagnosticArray, DiagnosticStatus
from overseer.model import FleetLimits, FleetModel
from overseer.model.events import Event
from overseer.model.transitions import TransitionDetector
from overseer.simulator.design import aggregated_statuses, initial_levels, leaf_components

ROBOTS = 1000
LEAVES = 45  # with their 5 groups: 50 components per robot
SECONDS = 30
SILENT_ROBOTS, SILENT_FROM, SILENT_UNTIL = 10, 5, 20
REALISTIC_CHANGES_PER_SECOND = 50
WORST_SECONDS = 6
FIRST_MESSAGE_TARGET_US = 50
BUSY_EVENTS, BUSY_BATCH = 100_000, 10_000
BUSY_TARGET = 50_000  # events a second beside a busy thread: 10,000 robots' 500,000 `appeared` in 10 s


class FleetClock:
    """Fleet time, moved by the benchmark."""

    def __init__(self) -> None:
        """Start at a fixed unix time."""
        self.now = 1_700_000_000.0

    def __call__(self) -> float:
        """The current fleet time."""
        return self.now


class Fleet:
    """One fleet model fed the benchmark's traffic, with or without the event history."""

    def __init__(self, statuses: tuple[DiagnosticStatus, ...], database: Path | None) -> None:
        """Apply every robot's first array; attach the history when `database` is given."""
        self.clock = FleetClock()
        limits = FleetLimits(max_robots=ROBOTS)
        self.model = FleetModel(limits, clock=self.clock)
        self.store: EventStore | None = None
        self.detector: TransitionDetector | None = None
        if database is not None:
            self.store = EventStore(StoreSettings(str(database), 30 * 86400.0, 10**10, queue_limit=10**7))
            self.detector = TransitionDetector(limits, self.store.add)
            self.model.set_level_listener(self.detector.on_level_changes)
        self.statuses = statuses
        self.revisions: dict[str, int] = {}
        for robot in range(ROBOTS):
            applied = self.model.apply_array(f"robot{robot}", DiagnosticArray(0, 0, "", statuses), "dds")
            assert applied.revision is not None
            self.revisions[f"robot{robot}"] = applied.revision
        self.settle()
        self.check_seconds = 0.0
        self.store_seconds = 0.0

    def settle(self) -> None:
        """Check and write what the first arrays made (every component appearing), outside the timing."""
        if self.detector is not None and self.store is not None:
            self.detector.check(self.model.snapshot())
            self.store.flush()

    def second(self, changes: Callable[[int], list[tuple[int, DiagnosticStatus]]], silent: set[int]) -> None:
        """One fleet second: every robot not `silent` publishes its `changes(robot)`; then check and store."""
        self.clock.now += 1.0
        model, revisions = self.model, self.revisions
        for robot in range(ROBOTS):
            if robot in silent:
                continue
            name = f"robot{robot}"
            revision = model.apply_changes(name, revisions[name], changes(robot), "dds")
            assert revision is not None
            revisions[name] = revision
        if self.detector is not None and self.store is not None:
            started = time.thread_time()
            self.detector.check(model.snapshot())
            checked = time.thread_time()
            self.store.flush()
            self.check_seconds += checked - started
            self.store_seconds += time.thread_time() - checked


def battery(statuses: tuple[DiagnosticStatus, ...]) -> int:
    return next(i for i, s in enumerate(statuses) if s.name == "/Power/Robot Battery")


def with_voltage(status: DiagnosticStatus, voltage: float) -> DiagnosticStatus:
    values = tuple((k, f"{voltage:.3f}" if k == "voltage" else v) for k, v in status.values)
    return status._replace(values=values)


def run(
    fleets: dict[str, Fleet], seconds: int, changes: Callable[[int, int], list[tuple[int, DiagnosticStatus]]]
) -> dict[str, float]:
    """CPU seconds each fleet's traffic took, the fleets taking turns second by second."""
    used = dict.fromkeys(fleets, 0.0)
    gc.collect()
    gc.freeze()  # the fleets as set up are long-lived: keep them out of the collections being timed
    for second in range(seconds):
        silent = set(range(SILENT_ROBOTS)) if SILENT_FROM <= second < SILENT_UNTIL else set()
        turns = list(fleets.items())
        for name, fleet in turns if second % 2 else reversed(turns):  # who goes first takes turns too
            started = time.thread_time()
            fleet.second(functools.partial(_at_second, changes, second), silent)
            used[name] += time.thread_time() - started
    return used


def _at_second(
    changes: Callable[[int, int], list[tuple[int, DiagnosticStatus]]], second: int, robot: int
) -> list[tuple[int, DiagnosticStatus]]:
    return changes(robot, second)


def realistic_changes(
    statuses: tuple[DiagnosticStatus, ...],
) -> Callable[[int, int], list[tuple[int, DiagnosticStatus]]]:
    """Every battery's voltage each second; 50 leaves a second toggling between OK and WARN."""
    battery_at = battery(statuses)
    leaves = [i for i, s in enumerate(statuses) if s.name.count("/") == 2 and i != battery_at]
    stride = ROBOTS // REALISTIC_CHANGES_PER_SECOND

    def changes(robot: int, second: int) -> list[tuple[int, DiagnosticStatus]]:
        changed = [(battery_at, with_voltage(statuses[battery_at], 11 + (robot + second) % 100 / 100))]
        if robot % stride == second % stride:  # each robot's turn comes every `stride` seconds: it toggles
            index = leaves[robot % len(leaves)]
            level = 1 if second // stride % 2 == 0 else 0
            changed.append((index, statuses[index]._replace(level=level, message=f"level {level}")))
        return changed

    return changes


def worst_changes(
    statuses: tuple[DiagnosticStatus, ...],
) -> Callable[[int, int], list[tuple[int, DiagnosticStatus]]]:
    """Every status changes level every second."""
    odd = [
        (i, s._replace(level=(s.level + 1) % 3, message=s.message + " (changed)"))
        for i, s in enumerate(statuses)
    ]
    even = list(enumerate(statuses))
    return lambda robot, second: odd if second % 2 == 0 else even


def store_figures(directory: Path) -> tuple[float, dict[str, float]]:
    """Events a CPU second the store writes in batches of 10,000, then query times on what it wrote.

    The queries run on 200,000 events of 1,000 robots: the API's newest page, one robot's, a level
    filter, and a component substring that matches one event in a thousand (a scan of the time index).
    """
    store = EventStore(
        StoreSettings(str(directory / "throughput.db"), 30 * 86400.0, 10**10, queue_limit=10**7)
    )
    values = (("voltage", "11.2"), ("current", "1.5"))
    written, used = 0, 0.0
    for batch in range(20):
        events = [
            Event(
                1e9 + batch * 10 + i / 1000,
                f"robot{i % ROBOTS}",
                "level",
                "/Temp/Sensor1" if i % 1000 else "/Laser/Rare",
                "temp1",
                Level.OK,
                Level.ERROR if i % 2 else Level.WARN,
                "too hot",
                values,
            )
            for i in range(10_000)
        ]
        store.add(events)
        started = time.thread_time()
        written += store.flush()
        used += time.thread_time() - started
    queries = {
        "newest 100": EventQuery(),
        "one robot's newest 100": EventQuery(robot="robot500"),
        "level=WARN, newest 100": EventQuery(levels=(Level.WARN,)),
        "a rare component substring, 100": EventQuery(component="Rare"),
    }
    latency = {}
    for name, query in queries.items():
        runs = []
        for _ in range(5):
            started = time.perf_counter()
            store.query(query)
            runs.append(time.perf_counter() - started)
        latency[name] = min(runs)
    store.stop()
    return written / used, latency


def busy_interpreter_figures(directory: Path) -> dict[str, float]:
    """Events a second the store writes while another thread keeps the interpreter busy, and alone.

    As when a whole fleet is first heard: the ingest runs flat out while the writer stores every
    robot's `appeared` events. Each SQLite statement lets go of the interpreter lock and waits for it
    back, so what matters is how many statements a batch takes. The shipped writer, alone and beside a
    busy thread, against one row a statement (`executemany`, as it wrote until 2026-11-27) beside it.
    """
    store = EventStore(StoreSettings(str(directory / "busy.db"), 30 * 86400.0, 10**10, queue_limit=10**7))
    values = (("voltage", "11.2"), ("current", "1.5"), ("temperature", "41.5"))

    def batch(first: int, count: int) -> list[Event]:
        return [
            Event(
                1e9 + i / 1000,
                f"robot{i // 50}",
                "appeared",
                f"/Sensors/S{i % 50}",
                "hw",
                None,
                Level.OK,
                "ok",
                values,
            )
            for i in range(first, first + count)
        ]

    def shipped(first: int, count: int) -> None:
        for start in range(first, first + count, BUSY_BATCH):
            store.add(batch(start, BUSY_BATCH))
            store.flush()

    def one_row_a_statement(first: int, count: int) -> None:
        writer = store._writer
        assert writer is not None
        rows = [(*event[:5], None, int(Level.OK), event.message, "[]") for event in batch(first, count)]
        writer.execute("BEGIN IMMEDIATE")
        writer.executemany(insert_statement(1), rows)
        writer.execute("COMMIT")

    figures = {"shipped, alone": _events_a_second(shipped, 0, BUSY_EVENTS, busy=False)}
    figures["shipped, beside a busy thread"] = _events_a_second(shipped, BUSY_EVENTS, BUSY_EVENTS, busy=True)
    figures["one row a statement, beside a busy thread"] = _events_a_second(
        one_row_a_statement, 2 * BUSY_EVENTS, BUSY_EVENTS // 50, busy=True
    )
    store.stop()
    return figures


def _events_a_second(write: Callable[[int, int], None], first: int, count: int, busy: bool) -> float:
    """Events a wall-clock second `write(first, count)` stores, beside a busy thread if `busy`."""
    with busy_interpreter() if busy else contextlib.nullcontext():
        started = time.perf_counter()
        write(first, count)
        return count / (time.perf_counter() - started)


def first_message_events(statuses: tuple[DiagnosticStatus, ...]) -> float:
    """Seconds the detector takes to make a robot's 50 `appeared` events from its first message's changes.

    Made in the thread that applied the message: at an exporter's first start beside a running fleet
    every robot makes them within a second, while every robot's array must be read whole.
    """
    changes: list[Any] = []
    model = FleetModel(FleetLimits(max_robots=1))
    model.set_level_listener(lambda _robot, _at, made: changes.extend(made))
    model.apply("robot0", DiagnosticArray(0, 0, "", statuses), "dds")
    detector = TransitionDetector(model.limits, lambda _events: None)
    rounds = 2000
    started = time.thread_time()
    for _ in range(rounds):
        detector.on_level_changes("robot0", 1.0, changes)
    return (time.thread_time() - started) / rounds


def main() -> None:
    """Measure and print the rows."""
    leaves = leaf_components(LEAVES)
    statuses = tuple(aggregated_statuses(leaves, initial_levels(leaves, 0, 0), set()))
    assert len(statuses) == 50
    rows: list[Row] = []
    with tempfile.TemporaryDirectory() as directory:
        fleets = {
            "plain": Fleet(statuses, None),
            "history": Fleet(statuses, Path(directory) / "realistic.db"),
        }
        used = run(fleets, SECONDS, realistic_changes(statuses))
        history = fleets["history"]
        assert history.store is not None
        events = history.store.stats().written - ROBOTS * 51  # less the first arrays' appeared and robot_up
        cost = (used["history"] - used["plain"]) / SECONDS
        rows += [
            Row(
                "events",
                "realistic: events a fleet second (level changes, robots down and up)",
                events / SECONDS,
                "events/s",
            ),
            Row(
                "events",
                "realistic: CPU of detection + storage, a core's share",
                100 * cost,
                "%",
                "<= 2 %",
                cost <= 0.02,
            ),
            Row(
                "events",
                "realistic: ... of which the snapshot check",
                1000 * history.check_seconds / SECONDS,
                "ms/s",
            ),
            Row(
                "events",
                "realistic: ... of which writing to SQLite",
                1000 * history.store_seconds / SECONDS,
                "ms/s",
            ),
            Row(
                "events",
                "realistic: the model's own apply, a core's share (for scale)",
                100 * used["plain"] / SECONDS,
                "%",
            ),
        ]
        worst = {"plain": Fleet(statuses, None), "history": Fleet(statuses, Path(directory) / "worst.db")}
        used = run(worst, WORST_SECONDS, worst_changes(statuses))
        history = worst["history"]
        assert history.store is not None
        events = history.store.stats().written - ROBOTS * 51
        cost = (used["history"] - used["plain"]) / WORST_SECONDS
        rows += [
            Row(
                "events",
                "worst case: events a fleet second (every component changes)",
                events / WORST_SECONDS,
                "events/s",
            ),
            Row(
                "events",
                "worst case: CPU of detection + storage, a core's share",
                100 * cost,
                "%",
            ),
            Row(
                "events",
                "worst case: ... of which writing to SQLite",
                1000 * history.store_seconds / WORST_SECONDS,
                "ms/s",
            ),
            Row(
                "events",
                "worst case: the model's own apply, a core's share (for scale)",
                100 * used["plain"] / WORST_SECONDS,
                "%",
            ),
        ]
        first = first_message_events(statuses)
        rows.append(
            Row(
                "events",
                "a robot's first message: its 50 appeared events made",
                first * 1e6,
                "µs a robot",
                f"<= {FIRST_MESSAGE_TARGET_US} (a robot's first array costs ~190)",
                first * 1e6 <= FIRST_MESSAGE_TARGET_US,
            )
        )
        throughput, latency = store_figures(Path(directory))
        rows.append(
            Row(
                "events",
                "store: write throughput, batches of 10,000",
                throughput,
                "events/CPU s",
                ">= 50,000 (the worst case's rate)",
                throughput >= 50_000,
            )
        )
        for name, seconds in latency.items():
            rows.append(Row("events", f"query on 200,000 events: {name}", 1000 * seconds, "ms"))
        busy = busy_interpreter_figures(Path(directory))
        for name, rate in busy.items():
            beside = name == "shipped, beside a busy thread"
            target = f">= {BUSY_TARGET:,}" if beside else ""
            rows.append(
                Row(
                    "events",
                    f"store: {name}",
                    rate,
                    "events/s",
                    target,
                    rate >= BUSY_TARGET if beside else None,
                )
            )
        ratio = busy["shipped, beside a busy thread"] / busy["one row a statement, beside a busy thread"]
        rows.append(Row("events", "store beside a busy thread: shipped / one row a statement", ratio, "x"))
    emit(rows)


if __name__ == "__main__":
    main()
