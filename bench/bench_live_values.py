"""Live values at fleet scale: every status changes at every publication, through ingest workers.

Robots publish over Zenoh through one router (a router-mode session in its own process) exactly as
rmw_zenoh does (or, with `--transport dds`, over DDS on loopback), with `--vary-values all`: each of a
robot's statuses carries a reading that changes at every publication, so no status repeats the one
before and the ingest's unchanged-status shortcut never applies. One simulator process per 2,500 robots
publishes at 1 Hz for the given time, after the exporter's subscription matches.

Per fleet size: lost updates (published minus received over the whole run), the exporter's CPU (its
process and its ingest workers) over the first 60 % of the run, with no scrape, its resident memory (all
its processes), how long a scrape of /metrics takes in the rest of the run (one every 3 s: every series
changed since the last), and the publishers' CPU, which competes with the exporter for this machine's
cores. The smallest fleet also runs with one worker, in the same run, for the ratio workers bring.
`statuses per exporter core-second` is what one core ingests: times the cores of a bigger server, it
predicts the fleet that server keeps up with.
"""

from __future__ import annotations

import argparse
import os
import re
import statistics
import tempfile
import time
import urllib.request
from pathlib import Path

from bench.common import Row, cpu_seconds, emit, tree_cpu_seconds, tree_resident_bytes
from bench.fleet_publishers import messages_published, start_publishers
from testbed.ports import fresh_domain_id
from testbed.processes import running_exporter
from testbed.zenoh import exporter_args, running_router_process, simulator_args

AGGREGATOR_GROUPS = 5  # the simulated aggregator adds a group status per 10 leaves (5 for 50)


def received(url: str, transport: str) -> float:
    """overseer_messages_total of messages received over `transport`."""
    with urllib.request.urlopen(url + "/metrics", timeout=120) as response:
        text = response.read().decode()
    match = re.search(rf'overseer_messages_total\{{result="received",transport="{transport}"\}} (\S+)', text)
    return float(match.group(1)) if match else 0.0


def scrape_seconds(url: str) -> float:
    """How long one scrape of /metrics takes, body read."""
    started = time.perf_counter()
    with urllib.request.urlopen(url + "/metrics", timeout=120) as response:
        response.read()
    return time.perf_counter() - started


def run(
    robots: int,
    components: int,
    seconds: float,
    workers: int,
    transport: str = "zenoh",
    zenoh_defaults: bool = False,
) -> list[Row]:
    """Publish `robots` x `components` live values at 1 Hz for `seconds` through `workers` workers.

    The router runs with the shipped configuration, or Zenoh's defaults when `zenoh_defaults`.
    """
    domain = fresh_domain_id()
    with (
        tempfile.TemporaryDirectory() as tmp,
        running_router_process(Path(tmp), zenoh_defaults) as (port, router),
        running_exporter(
            Path(tmp),
            domain if transport == "dds" else None,
            *(exporter_args(port) if transport == "zenoh" else ()),
            f"--ingest.workers={workers}",
            "--log.level=warning",
        ) as exporter,
    ):
        pid = exporter.process.pid
        transport_args = (
            simulator_args(port) if transport == "zenoh" else (f"--domain={domain}", "--dds.loopback-only")
        )
        simulators = start_publishers(robots, components, seconds, transport_args, "all")
        while received(exporter.url, transport) == 0 and simulators[0].poll() is None:
            time.sleep(0.2)
        # Ingest alone first (no scrape: one renders every series, all changed), then scrapes every 3 s.
        window = 0.6 * seconds
        exporter_cpu = tree_cpu_seconds(pid)
        publisher_cpu = sum(cpu_seconds(simulator.pid) for simulator in simulators)
        router_cpu = cpu_seconds(router.process.pid)
        time.sleep(window)
        ingest_cpu = tree_cpu_seconds(pid) - exporter_cpu
        publisher_cpu = sum(cpu_seconds(simulator.pid) for simulator in simulators) - publisher_cpu
        router_cpu = cpu_seconds(router.process.pid) - router_cpu
        scrapes = []
        while all(simulator.poll() is None for simulator in simulators):
            scrapes.append(scrape_seconds(exporter.url))
            time.sleep(max(0.0, 3.0 - scrapes[-1]))
        published = messages_published(simulators, seconds + 1800)
        time.sleep(4)
        got = received(exporter.url, transport)
        rss = tree_resident_bytes(pid)
    lost = max(0.0, published - got)
    # The window's statuses: the fleet's rate, scaled by the share that arrived over the whole run.
    statuses = robots * (components + AGGREGATOR_GROUPS) * window * (got / published if published else 0.0)
    plural = "s" if workers > 1 else ""
    label = f"{transport}, {robots} robots x {components} live at 1 Hz, {workers} worker{plural}"
    label += ", router with Zenoh's defaults" if zenoh_defaults else ""
    # Zenoh's defaults are there to compare with: the target is the shipped router's.
    lost_target = ("", None) if zenoh_defaults else ("0", lost == 0)
    return [
        Row("live values", f"{label}: messages published", published, "messages"),
        Row(
            "live values",
            f"{label}: publications achieved",
            published / (robots * seconds) * 100,
            "% of 1 Hz",
        ),
        Row("live values", f"{label}: lost updates", lost, "messages", *lost_target),
        Row("live values", f"{label}: lost share", lost / published * 100 if published else 0.0, "%"),
        Row("live values", f"{label}: exporter CPU ingesting", ingest_cpu / window * 100, "% of a core"),
        Row(
            "live values",
            f"{label}: statuses per exporter core-second",
            statuses / ingest_cpu if ingest_cpu else 0.0,
            "statuses",
        ),
        Row("live values", f"{label}: exporter resident memory", rss / 1e6, "MB"),
        Row(
            "live values",
            f"{label}: scrape while publishing (median)",
            statistics.median(scrapes) * 1000 if scrapes else 0.0,
            "ms",
        ),
        Row("live values", f"{label}: publishers' CPU", publisher_cpu / window * 100, "% of a core"),
        Row("live values", f"{label}: router CPU", router_cpu / window * 100, "% of a core"),
    ]


def main() -> None:
    """The smallest fleet with one worker and with one per core, then every fleet with one per core.

    Over Zenoh, the smallest fleet with one worker runs through a router with Zenoh's defaults too.
    """
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--robots", type=int, nargs="+", default=[1000, 5000, 10000])
    parser.add_argument("--components", type=int, default=50)
    parser.add_argument("--seconds", type=float, default=20)
    parser.add_argument("--workers", type=int, default=len(os.sched_getaffinity(0)))
    parser.add_argument("--transport", choices=["zenoh", "dds"], default="zenoh")
    options = parser.parse_args()
    rows = run(options.robots[0], options.components, options.seconds, 1, options.transport)
    if options.transport == "zenoh":
        rows += run(options.robots[0], options.components, options.seconds, 1, zenoh_defaults=True)
    for robots in options.robots:
        rows += run(robots, options.components, options.seconds, options.workers, options.transport)
    emit(rows)


if __name__ == "__main__":
    main()
