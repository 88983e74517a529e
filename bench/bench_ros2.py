"""ROS 2 through rclpy against the DDS source: one real Jazzy fleet, both exporters listening, one run.

Simulated robots publish from real rclpy nodes (`overseer simulate --transport ros2`, 250 robots a
process) at 1 Hz on a ROS domain of this run's own, on loopback. Two exporters follow them at once, each
ingesting in its own process (`--ingest.workers 1`): one joins the graph as a ROS 2 node (`--ros2`), the
other reads the same topics with Cyclone DDS. The publishers wait until both subscribe to every robot.
Two rounds: robots republishing the same arrays, then every status changing at every publication
(`--vary-values all`, the live-values worst case). Per exporter: lost updates over the run, CPU of its
process over a window in the middle of the run (no scrape), and resident memory.
"""

from __future__ import annotations

import argparse
import re
import tempfile
import time
import urllib.request
from contextlib import ExitStack
from pathlib import Path

from bench.common import Row, cpu_seconds, emit, resident_bytes
from bench.fleet_publishers import messages_published, start_publishers
from testbed.ports import fresh_domain_id
from testbed.processes import Exporter, running_exporter
from testbed.ros2 import ros2_environment

TARGET_CPU = 60.0  # % of a core, for --ros2 at 1,000 robots x 50 components
PER_PROCESS = 250


def received(exporter: Exporter, transport: str) -> float:
    """overseer_messages_total of messages received over `transport`."""
    with urllib.request.urlopen(exporter.url + "/metrics", timeout=120) as response:
        text = response.read().decode()
    match = re.search(rf'overseer_messages_total\{{result="received",transport="{transport}"\}} (\S+)', text)
    return float(match.group(1)) if match else 0.0


def run(robots: int, components: int, seconds: float, vary_values: str) -> list[Row]:
    """Both exporters on one rclpy fleet publishing for `seconds`."""
    domain = fresh_domain_id()
    environment = ros2_environment(domain)
    with tempfile.TemporaryDirectory() as tmp, ExitStack() as stack:
        ros2 = stack.enter_context(
            running_exporter(
                Path(tmp),
                None,
                "--ros2",
                "--ros2.fleet-topic=/bench/fleet_diagnostics",
                "--ingest.workers=1",
                "--log.level=warning",
                env=environment,
                loopback_flag=False,
            )
        )
        dds = stack.enter_context(
            running_exporter(Path(tmp), domain, "--ingest.workers=1", "--log.level=warning")
        )
        transport_args = (f"--domain={domain}", "--dds.loopback-only", "--transport=ros2", "--subscribers=2")
        publishers = start_publishers(
            robots, components, seconds, transport_args, vary_values, PER_PROCESS, environment
        )
        exporters = {"ros2": ros2, "dds": dds}
        while all(received(exporter, name) == 0 for name, exporter in exporters.items()):
            time.sleep(0.2)
        time.sleep(0.2 * seconds)
        window = 0.6 * seconds
        cpu = {name: cpu_seconds(exporter.process.pid) for name, exporter in exporters.items()}
        time.sleep(window)
        cpu = {name: cpu_seconds(exporter.process.pid) - cpu[name] for name, exporter in exporters.items()}
        rss = {name: resident_bytes(exporter.process.pid) for name, exporter in exporters.items()}
        published = messages_published(publishers, seconds + 1800)
        time.sleep(4)
        got = {name: received(exporter, name) for name, exporter in exporters.items()}
    kind = "live values" if vary_values == "all" else "republished"
    label = f"{robots} robots x {components} at 1 Hz, {kind}"
    rows = [Row("ros2", f"{label}: messages published", published, "messages")]
    for name in ("ros2", "dds"):
        lost = max(0.0, published - got[name])
        share = cpu[name] / window * 100
        source = "--ros2 (rclpy)" if name == "ros2" else "DDS source (Cyclone)"
        target = f"<= {TARGET_CPU:g}" if name == "ros2" else ""
        rows += [
            Row("ros2", f"{label}: {source}, lost updates", lost, "messages", "0", lost == 0),
            Row(
                "ros2",
                f"{label}: {source}, CPU ingesting",
                share,
                "% of a core",
                target,
                share <= TARGET_CPU if target else None,
            ),
            Row("ros2", f"{label}: {source}, resident memory", rss[name] / 1e6, "MB"),
        ]
    return rows


def main() -> None:
    """Republished, then live values, at the given fleet size."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0] if __doc__ else None)
    parser.add_argument("--robots", type=int, default=1000)
    parser.add_argument("--components", type=int, default=50)
    parser.add_argument("--seconds", type=float, default=30)
    options = parser.parse_args()
    emit(
        run(options.robots, options.components, options.seconds, "none")
        + run(options.robots, options.components, options.seconds, "all")
    )


if __name__ == "__main__":
    main()
