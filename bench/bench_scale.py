"""One exporter under the load generator's fleet: lost updates, CPU per message, memory, /metrics, by size.

`python -m bench.bench_scale --robots 1000,3000 --workers 1,2` runs, for each size and worker count,
one Python Zenoh router, `overseer run --dds.disabled --zenoh.connect ROUTER --ingest.workers W`, and
the load generator (`bench.loadgen`) publishing N robots x 50 components at 1 Hz as rmw_zenoh does,
with the realistic profile (1 % of statuses changing a second, 2 % of robots in trouble) unless
`--profile live`. The generator waits until the exporter's subscriptions match every robot, so the
ramp-up (every robot's first array) is inside the window. Lost updates = messages the generator
published minus messages the exporter counted as received; CPU is the exporter's processes' (main and
workers) over the window; the generator's own CPU per 1,000 robots is printed beside every figure.
"""

from __future__ import annotations

import argparse
import re
import tempfile
import time
import urllib.request
from pathlib import Path

from bench.common import Row, cpu_seconds, emit, tree_cpu_seconds, tree_resident_bytes
from bench.loadgen import running_loadgen
from testbed.processes import running_exporter
from testbed.zenoh import endpoint, exporter_args, running_router_process

COMPONENTS = 50
SETTLE_SECONDS = 4.0  # after the generator stops, for the last samples to be counted


def received(url: str) -> float:
    """overseer_messages_total{result="received"} over Zenoh."""
    with urllib.request.urlopen(url + "/metrics", timeout=300) as response:
        text = response.read().decode()
    match = re.search(r'overseer_messages_total\{result="received",transport="zenoh"\} (\S+)', text)
    return float(match.group(1)) if match else 0.0


def scrape(url: str) -> tuple[float, int]:
    """Seconds and bytes of one `/metrics` read as Prometheus asks for it (text format)."""
    request = urllib.request.Request(url + "/metrics", headers={"Accept": "text/plain;version=0.0.4"})
    started = time.perf_counter()
    with urllib.request.urlopen(request, timeout=300) as response:
        size = len(response.read())
    return time.perf_counter() - started, size


def run(robots: int, workers: int, profile: str, seconds: float) -> list[Row]:
    """Publish `robots` x 50 at 1 Hz for `seconds` into an exporter with `workers` ingest workers."""
    label = f"{robots} robots x {COMPONENTS}, {profile}, {workers} worker{'s' if workers > 1 else ''}"
    with (
        tempfile.TemporaryDirectory() as tmp,
        running_router_process(Path(tmp)) as (port, router),
        running_exporter(
            Path(tmp),
            None,
            *exporter_args(port),
            f"--ingest.workers={workers}",
            f"--fleet.max-robots={2 * robots}",  # the cap is shared out by hash: headroom, not a limit
            "--log.level=warning",
        ) as exporter,
    ):
        pid = exporter.process.pid
        started_cpu, router_cpu, started = tree_cpu_seconds(pid), cpu_seconds(router.process.pid), 0.0
        with running_loadgen(
            [
                f"--robots={robots}",
                f"--profile={profile}",
                f"--zenoh.connect={endpoint(port)}",
                "--zenoh.listen=tcp/127.0.0.1:0",
                f"--wait-for-subscribers={max(60, robots / 50)}",
                f"--duration={seconds}",
            ],
            Path(tmp),
        ) as loadgen:
            loadgen.wait_ready(max(60, robots / 50))
            started, started_cpu = time.monotonic(), tree_cpu_seconds(pid)
            router_cpu = cpu_seconds(router.process.pid)
            figures = loadgen.figures(seconds + 600)
        time.sleep(SETTLE_SECONDS)
        elapsed = time.monotonic() - started
        cpu = tree_cpu_seconds(pid) - started_cpu
        router_cpu = cpu_seconds(router.process.pid) - router_cpu
        got = received(exporter.url)
        rss = tree_resident_bytes(pid)
        scrape_seconds, scrape_bytes = min(scrape(exporter.url) for _ in range(3))
    lost = max(0.0, figures.published - got)
    generator = f"(generator {figures.cpu_percent_per_1000_robots:.1f} % of a core per 1,000 robots)"
    return [
        Row("scale", f"{label}: published {generator}", figures.published, "messages"),
        Row("scale", f"{label}: lost updates", lost, "messages", "0", lost == 0),
        Row("scale", f"{label}: exporter CPU", cpu / elapsed * 100, "% of a core", "<= 100", cpu <= elapsed),
        Row("scale", f"{label}: exporter CPU a message", cpu / max(got, 1) * 1e6, "µs"),
        Row("scale", f"{label}: exporter memory a component", rss / (robots * COMPONENTS), "bytes"),
        Row("scale", f"{label}: router CPU", router_cpu / elapsed * 100, "% of a core"),
        Row("scale", f"{label}: /metrics read", scrape_seconds, "s"),
        Row("scale", f"{label}: /metrics body", scrape_bytes / 1e6, "MB"),
    ]


def main() -> None:
    """Every size x worker count asked for, one after the other."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--robots", default="1000", help="comma-separated fleet sizes (default 1000)")
    parser.add_argument("--workers", default="1,2", help="comma-separated worker counts (default 1,2)")
    parser.add_argument("--profile", default="realistic", choices=["realistic", "live"])
    parser.add_argument("--seconds", type=float, default=60)
    options = parser.parse_args()
    rows: list[Row] = []
    for robots in [int(size) for size in options.robots.split(",")]:
        for workers in [int(count) for count in options.workers.split(",")]:
            rows += run(robots, workers, options.profile, options.seconds)
    emit(rows)


if __name__ == "__main__":
    main()
