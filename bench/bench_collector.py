"""Python's cycle collector in the exporter's process at 10,000 robots: its share of the ingest, its pauses.

In process, no network: the Zenoh source is handed every robot's samples as Zenoh gives them (key,
payload, attachment), from the load generator's fleet (`bench.loadgen_payloads`, realistic profile:
1 % of statuses changing a second), 50 components a robot, at 1 Hz of a fleet clock, with the event
history's detector and a store on a real SQLite file flushed every fleet second. First every robot's
first array (the ramp-up), then `--seconds` fleet seconds of steady traffic. Each setting runs in a
fresh process, Python's default thresholds and the exporter's (`overseer.garbage_collection`) taking
turns, so the two are compared in one sitting. CPU includes everything the process did (building the
samples too, which is the same for both); the collector's time and its longest pause come from
`gc.callbacks`. Target: no pause of the collector over 100 ms in the steady fleet (a change must reach
`/metrics` within 1 s, and a pause holds every thread).
"""

from __future__ import annotations

import argparse
import gc
import json
import os
import struct
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

from bench.bench_first_look import aggregator_addresses
from bench.common import Row, emit
from bench.loadgen_payloads import Fleet, FleetShape
from overseer.config.zenoh import ZenohConfig
from overseer.garbage_collection import collect_in_large_batches
from overseer.history.store import EventStore, StoreSettings
from overseer.model import FleetLimits, FleetModel
from overseer.model.transitions import TransitionDetector
from overseer.sources.zenoh.source import ZenohSource

DEFAULT, TUNED = "Python's default thresholds", "the exporter's thresholds"
PAUSE_TARGET = 0.1  # seconds: the longest collection in the steady fleet
_STAMP = struct.Struct("<iI")


class CollectorWatch:
    """Time spent in the cycle collector and its longest pause, from `gc.callbacks`."""

    def __init__(self) -> None:
        """Start watching."""
        self.collections = 0
        self.seconds = 0.0
        self.longest = 0.0
        self._started = 0.0
        gc.callbacks.append(self._on_phase)

    def reset(self) -> None:
        """Count from now on."""
        self.collections, self.seconds, self.longest = 0, 0.0, 0.0

    def _on_phase(self, phase: str, _info: dict[str, Any]) -> None:
        if phase == "start":
            self._started = time.perf_counter()
            return
        took = time.perf_counter() - self._started
        self.collections += 1
        self.seconds += took
        self.longest = max(self.longest, took)


def measure(robots: int, seconds: int, tuned: bool) -> dict[str, float]:
    """One setting's figures: first arrays and steady traffic through the Zenoh source and the history."""
    if tuned:
        collect_in_large_batches()
    watch = CollectorWatch()
    fleet = Fleet(FleetShape(robots))
    clock = [1_700_000_000.0]
    model = FleetModel(FleetLimits(max_robots=2 * robots), clock=lambda: clock[0])
    database = os.path.join(tempfile.mkdtemp(), "events.db")
    store = EventStore(StoreSettings(database, 86400.0, 10**10, queue_limit=10**7))
    detector = TransitionDetector(model.limits, store.add)
    model.set_level_listener(detector.on_level_changes)
    on_sample = ZenohSource(ZenohConfig(enabled=True), model).ingest.on_sample  # what the session hands on
    addresses = aggregator_addresses(robots)

    def fleet_second(second: int) -> None:
        fleet.advance(float(second))
        stamp = _STAMP.pack(second, 0)
        for (key, robot_attachment), payload in zip(addresses, fleet.payloads, strict=True):
            payload[4:12] = stamp
            on_sample(key, robot_attachment, bytes(payload))
        clock[0] += 1.0
        detector.check(model.snapshot())
        store.flush()

    started = time.process_time()
    fleet_second(0)
    first = time.process_time() - started
    first_collector = watch.seconds
    watch.reset()
    started = time.process_time()
    for second in range(1, seconds + 1):
        fleet_second(second)
    steady = time.process_time() - started
    messages = robots * seconds
    return {
        "first_us": first / robots * 1e6,
        "first_collector_us": first_collector / robots * 1e6,
        "steady_us": steady / messages * 1e6,
        "steady_collector_us": watch.seconds / messages * 1e6,
        "collections": watch.collections,
        "longest": watch.longest,
    }


def main() -> None:
    """Run each setting in its own process, alternating, and print the rows."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n", 1)[0])
    parser.add_argument("--robots", type=int, default=10_000)
    parser.add_argument("--seconds", type=int, default=20, help="fleet seconds of steady traffic")
    parser.add_argument("--rounds", type=int, default=2, help="runs of each setting, alternating")
    parser.add_argument("--child", choices=("default", "tuned"), help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:
        print(json.dumps(measure(args.robots, args.seconds, args.child == "tuned")))
        return
    results: dict[str, list[dict[str, float]]] = {DEFAULT: [], TUNED: []}
    for _ in range(args.rounds):
        for label, child in ((DEFAULT, "default"), (TUNED, "tuned")):
            command = [sys.executable, "-m", "bench.bench_collector", "--child", child]
            command += [f"--robots={args.robots}", f"--seconds={args.seconds}"]
            output = subprocess.run(command, check=True, capture_output=True, text=True, cwd=Path.cwd())
            results[label].append(json.loads(output.stdout.splitlines()[-1]))
    emit(rows(args.robots, results))


def rows(robots: int, results: dict[str, list[dict[str, float]]]) -> list[Row]:
    """Each setting's best run (least steady CPU), and the ratio of the two."""
    table = []
    best = {label: min(runs, key=lambda run: run["steady_us"]) for label, runs in results.items()}
    for label, run in best.items():
        prefix = f"{robots:,} robots x 50, {label}"
        worst_pause = max(r["longest"] for r in results[label])
        table += [
            Row("collector", f"{prefix}: a robot's first array", run["first_us"], "µs"),
            Row("collector", f"{prefix}: of which the collector", run["first_collector_us"], "µs"),
            Row("collector", f"{prefix}: a steady message", run["steady_us"], "µs"),
            Row("collector", f"{prefix}: of which the collector", run["steady_collector_us"], "µs"),
            Row("collector", f"{prefix}: collections in the steady fleet", run["collections"], ""),
            Row(
                "collector",
                f"{prefix}: longest collection in the steady fleet (of {len(results[label])} runs)",
                worst_pause * 1e3,
                "ms",
                *((f"<= {PAUSE_TARGET * 1e3:g}", worst_pause <= PAUSE_TARGET) if label == TUNED else ()),
            ),
        ]
    ratio = best[TUNED]["steady_us"] / best[DEFAULT]["steady_us"]
    table.append(Row("collector", f"{robots:,} robots: a steady message, tuned / default", ratio, "x"))
    return table


if __name__ == "__main__":
    main()
