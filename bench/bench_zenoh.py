"""End to end over Zenoh: a fleet at 1 Hz through one router, beside the same fleet over DDS in the same run.

The simulator (one process, one Zenoh session, publishing exactly as rmw_zenoh does, with voltages that
change at every publication) waits until the exporter's subscription matches every robot, then
publishes for the given time through one Zenoh router (a router-mode session in its own process).
Lost updates = messages the simulator wrote minus messages the exporter counted as received. The same
fleet over DDS (as `bench_fleet` runs it) is measured the same way in the same run, so the two compare
on equal terms; then a fleet ten times larger goes over Zenoh alone, to show what one exporter keeps up
with. Exporter CPU is counted from the first message received to the end of the run.
"""

from __future__ import annotations

import argparse
import re
import tempfile
import time
import urllib.request
from pathlib import Path

from bench.common import Row, cpu_seconds, emit, tree_cpu_seconds, tree_resident_bytes
from bench.fleet_publishers import messages_published, start_publishers
from testbed.ports import fresh_domain_id
from testbed.processes import running_exporter
from testbed.zenoh import exporter_args, running_router_process, simulator_args


def counted(url: str, transport: str, result: str) -> float:
    """overseer_messages_total for `transport` with `result`."""
    with urllib.request.urlopen(url + "/metrics", timeout=120) as response:
        text = response.read().decode()
    match = re.search(rf'overseer_messages_total\{{result="{result}",transport="{transport}"\}} (\S+)', text)
    return float(match.group(1)) if match else 0.0


def run(transport: str, robots: int, components: int, seconds: float) -> list[Row]:
    """Publish `robots` x `components` at 1 Hz over `transport` for `seconds`: losses, CPU, memory."""
    domain = fresh_domain_id()
    publish = (
        simulator_args if transport == "zenoh" else lambda _: (f"--domain={domain}", "--dds.loopback-only")
    )
    with (
        tempfile.TemporaryDirectory() as tmp,
        running_router_process(Path(tmp)) as (port, router),
        running_exporter(
            Path(tmp),
            domain if transport == "dds" else None,
            *(exporter_args(port) if transport == "zenoh" else ()),
            "--log.level=warning",
        ) as exporter,
    ):
        pid = exporter.process.pid
        simulators = start_publishers(robots, components, seconds, publish(port), "battery")
        # CPU is measured from the first message received to the end: subscribing to the fleet is not ingest.
        while counted(exporter.url, transport, "received") == 0 and simulators[0].poll() is None:
            time.sleep(0.2)
        started, started_cpu, router_cpu = (
            time.monotonic(),
            tree_cpu_seconds(pid),
            cpu_seconds(router.process.pid),
        )
        published = messages_published(simulators, seconds + 1800)
        time.sleep(4)
        elapsed = time.monotonic() - started
        cpu = tree_cpu_seconds(pid) - started_cpu
        router_cpu = cpu_seconds(router.process.pid) - router_cpu
        got = counted(exporter.url, transport, "received")
        undecodable = counted(exporter.url, transport, "decode_error")
        rss = tree_resident_bytes(pid)
    lost = max(0.0, published - got)
    label = f"{transport}, {robots} robots x {components} components at 1 Hz"
    rows = [
        Row("zenoh", f"{label}: messages published", published, "messages"),
        Row("zenoh", f"{label}: publications achieved", published / (robots * seconds) * 100, "% of 1 Hz"),
        Row("zenoh", f"{label}: lost updates", lost, "messages", "0", lost == 0),
        Row("zenoh", f"{label}: lost share", lost / published * 100 if published else 0.0, "%"),
        Row("zenoh", f"{label}: undecodable", undecodable, "messages", "0", undecodable == 0),
        Row("zenoh", f"{label}: exporter CPU while publishing", cpu / elapsed * 100, "% of a core"),
        Row("zenoh", f"{label}: exporter resident memory", rss / 1e6, "MB"),
    ]
    if transport == "zenoh":
        rows.append(
            Row("zenoh", f"{label}: router CPU while publishing", router_cpu / elapsed * 100, "% of a core")
        )
    return rows


def main() -> None:
    """1,000 x 50 over Zenoh and over DDS side by side, then 10,000 x 50 over Zenoh."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--robots", type=int, default=1000)
    parser.add_argument("--large-robots", type=int, default=10000, help="the larger fleet (0: skip it)")
    parser.add_argument("--components", type=int, default=50)
    parser.add_argument("--seconds", type=float, default=30)
    options = parser.parse_args()
    rows = run("zenoh", options.robots, options.components, options.seconds)
    rows += run("dds", options.robots, options.components, options.seconds)
    if options.large_robots:
        rows += run("zenoh", options.large_robots, options.components, options.seconds)
    emit(rows)


if __name__ == "__main__":
    main()
