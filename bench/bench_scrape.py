"""Scrape: /metrics latency and size, plain and gzip, against a naive prometheus-client exporter.

Both serve the same series over real HTTP on loopback, in this process: Overseer's exporter from its
fleet model, and the naive one from `Gauge.labels(...).set()` on prometheus-client's own server.
Between Overseer's scrapes every robot republishes (a touch) or, in the "changing" rows, changes one
value, as a fleet with varying voltages does. The last row scrapes a real exporter whose ingest workers
(one per core) each hold part of a simulated DDS fleet.
"""

from __future__ import annotations

import contextlib
import re
import statistics
import threading
import time
import urllib.request

from prometheus_client import CollectorRegistry, Counter, Gauge, start_http_server

from bench.common import Row, emit
from overseer.messages import DiagnosticArray
from overseer.model import FleetLimits, FleetModel
from overseer.serve.exposition import FleetExposition
from overseer.serve.fleet_view import ModelView
from overseer.serve.http import OverseerServer
from overseer.serve.metrics import FleetCollector
from overseer.simulator.design import aggregated_statuses, initial_levels, leaf_components

LEAVES = 50
TARGET_MS = 250


def statuses_for(robot: int, version: int) -> DiagnosticArray:
    leaves = leaf_components(LEAVES)
    statuses = aggregated_statuses(leaves, initial_levels(leaves, 2, 2), set())
    voltage = f"{11 + robot / 1000 + version / 1e5:.5f}"
    varied = [
        s._replace(values=tuple((k, voltage if k == "voltage" else v) for k, v in s.values)) for s in statuses
    ]
    return DiagnosticArray(0, 0, "", tuple(varied))


def scrape_ms(url: str, gzip: bool, between: object = None, repeats: int = 7) -> tuple[float, int]:
    """Median latency of GET `url` and the body size."""
    timings, size = [], 0
    for _ in range(repeats):
        if callable(between):
            between()
        request = urllib.request.Request(url, headers={"Accept-Encoding": "gzip"} if gzip else {})
        started = time.perf_counter()
        with urllib.request.urlopen(request, timeout=120) as response:
            size = len(response.read())
        timings.append((time.perf_counter() - started) * 1000)
    return statistics.median(timings), size


def measure(series_wanted: int) -> list[Row]:
    model = FleetModel(FleetLimits(max_robots=100_000, stale_after=3600, robot_timeout=3600))
    robots = 0
    per_robot = 0
    while robots * per_robot < series_wanted:
        model.apply(f"robot{robots}", statuses_for(robots, 0), "dds")
        robots += 1
        if robots == 1:
            per_robot = FleetExposition(model, re.compile(".*"), ["dds"]).render().count(b"\n") - 34
    registry = CollectorRegistry()
    exposition = FleetExposition(model, re.compile(".*"), ["dds"])
    registry.register(FleetCollector(model, re.compile(".*"), ["dds"]))
    server = OverseerServer(("127.0.0.1", 0), ModelView(model, exposition), registry)
    threading.Thread(target=server.serve_forever, daemon=True).start()
    series = exposition.render().count(b"\n") - 34

    naive_registry = CollectorRegistry()
    level = Gauge(
        "ros_diagnostics_level", "level", ["robot", "component", "hardware_id"], registry=naive_registry
    )
    changes = Counter(
        "ros_diagnostics_level_changes",
        "changes",
        ["robot", "component", "hardware_id"],
        registry=naive_registry,
    )
    value = Gauge(
        "ros_diagnostics_value",
        "value",
        ["robot", "component", "hardware_id", "key"],
        registry=naive_registry,
    )
    snapshot = model.snapshot()
    for robot in snapshot.robots:
        for component in robot.components.values():
            labels = (robot.name, component.name, component.hardware_id)
            level.labels(*labels).set(float(component.level))
            changes.labels(*labels).inc(0)
            for key, text in component.values:
                with contextlib.suppress(ValueError):
                    value.labels(*labels, key).set(float(text))
    naive_server, _ = start_http_server(0, addr="127.0.0.1", registry=naive_registry)
    naive_url = f"http://127.0.0.1:{naive_server.server_address[1]}/metrics"
    url = f"{server.url}/metrics"

    names = [r.name for r in snapshot.robots]
    version = [0]

    def republish() -> None:
        for name in names:
            model.touch(name, "dds")

    def change() -> None:
        version[0] += 1
        for index, name in enumerate(names):
            model.apply(name, statuses_for(index, version[0]), "dds")

    rows = []
    label = f"{series // 1000}k series"
    for gzip in (False, True):
        kind = "gzip" if gzip else "plain"
        ours, size = scrape_ms(url, gzip, republish)
        changing, _ = scrape_ms(url, gzip, change, repeats=3)
        naive, _ = scrape_ms(naive_url, gzip, repeats=3)
        rows += [
            Row("scrape", f"{label}, {kind}: Overseer", ours, "ms", f"<= {TARGET_MS}", ours <= TARGET_MS),
            Row(
                "scrape",
                f"{label}, {kind}: Overseer, every robot changed",
                changing,
                "ms",
                f"<= {TARGET_MS}",
                changing <= TARGET_MS,
            ),
            Row("scrape", f"{label}, {kind}: naive Gauge.labels exporter", naive, "ms"),
            Row("scrape", f"{label}, {kind}: naive / Overseer", naive / ours, "x", ">= 4", naive / ours >= 4),
            Row("scrape", f"{label}, {kind}: body size", size / 1e6, "MB"),
        ]
    server.shutdown()
    naive_server.shutdown()
    return rows


def measure_workers(robots: int = 1000, components: int = 20, workers: int = 2) -> list[Row]:
    """A real exporter with ingest workers and a simulated DDS fleet: a scrape joins every worker's part."""
    import sys
    import tempfile
    from pathlib import Path

    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
    from support.ports import fresh_domain_id
    from support.processes import running_exporter, running_simulator, wait_for

    domain = fresh_domain_id()
    flags = (f"--ingest.workers={workers}", "--log.level=warning")
    with (
        tempfile.TemporaryDirectory() as tmp,
        running_exporter(Path(tmp), domain, *flags) as exporter,
        running_simulator(Path(tmp), domain, f"--robots={robots}", f"--components={components}"),
    ):

        def body() -> bytes:
            with urllib.request.urlopen(exporter.url + "/metrics", timeout=60) as response:
                return bytes(response.read())

        def every_robot_up() -> bool:
            robot_up = [line for line in body().split(b"\n") if line.startswith(b"ros_diagnostics_robot_up{")]
            return len(robot_up) == robots and all(line.endswith(b" 1.0") for line in robot_up)

        wait_for(every_robot_up, 120, message="every robot up")
        timings = []
        for _ in range(7):
            started = time.perf_counter()
            text = body()
            timings.append((time.perf_counter() - started) * 1000)
    series = sum(1 for line in text.split(b"\n") if line.startswith(b"ros_"))
    median = statistics.median(timings)
    label = f"{series // 1000}k series, plain, through {workers} ingest workers (robots republishing)"
    return [Row("scrape", label, median, "ms", f"<= {TARGET_MS}", median <= TARGET_MS)]


def main() -> None:
    """Measure at 10,000 and 100,000 series, then through ingest workers."""
    emit(measure(10_000) + measure(100_000) + measure_workers())


if __name__ == "__main__":
    main()
