"""End to end over DDS: the largest fleet at 1 Hz the exporter follows with no lost update, and its CPU.

The simulator (one process, one participant) publishes every robot's /diagnostics_agg at 1 Hz with
voltages that change at every publication (--vary-values: no array repeats the one before), after
waiting until the exporter has subscribed to every robot. Lost updates = messages the simulator wrote
minus messages the exporter counted as received.
"""

from __future__ import annotations

import argparse
import re
import subprocess
import sys
import tempfile
import time
import urllib.request
from pathlib import Path

from bench.common import Row, emit, tree_cpu_seconds, tree_resident_bytes
from testbed.ports import free_port, fresh_domain_id
from testbed.processes import running_exporter


def received(url: str) -> float:
    with urllib.request.urlopen(url + "/metrics", timeout=60) as response:
        text = response.read().decode()
    match = re.search(r'overseer_messages_total\{result="received",transport="dds"\} (\S+)', text)
    return float(match.group(1)) if match else 0.0


def run(robots: int, components: int, seconds: float) -> list[Row]:
    """Publish `robots` x `components` at 1 Hz for `seconds`; rows for losses and the exporter's CPU."""
    domain = fresh_domain_id()
    with (
        tempfile.TemporaryDirectory() as tmp,
        running_exporter(Path(tmp), domain, "--log.level=warning", port=free_port()) as exporter,
    ):
        simulator = subprocess.run(
            [
                sys.executable,
                "-m",
                "overseer.cli",
                "simulate",
                f"--domain={domain}",
                "--dds.loopback-only",
                f"--robots={robots}",
                f"--components={components}",
                "--warn=1",
                "--error=1",
                "--vary-values",
                "--wait-for-subscribers=120",
                f"--duration={seconds}",
                "--log.level=warning",
            ],
            capture_output=True,
            text=True,
            timeout=seconds + 300,
            check=False,
        )
        match = re.search(r"published (\d+) messages", simulator.stdout)
        if simulator.returncode != 0 or match is None:
            raise RuntimeError(f"simulator failed: {simulator.stdout[-2000:]} {simulator.stderr[-2000:]}")
        published = int(match.group(1))
        time.sleep(2)
        got = received(exporter.url)
        pid = exporter.process.pid
        cpu = tree_cpu_seconds(pid)
        rss = tree_resident_bytes(pid)
    statuses = robots * (components + 5)
    lost = max(0.0, published - got)
    label = f"{robots} robots x {components} components at 1 Hz"
    return [
        Row("fleet", f"{label}: messages published", published, "messages"),
        Row("fleet", f"{label}: lost updates", lost, "messages", "0", lost == 0),
        Row("fleet", f"{label}: statuses per second", statuses, "statuses/s"),
        Row("fleet", f"{label}: exporter CPU over the run", cpu / (seconds + 4) * 100, "% of a core"),
        Row("fleet", f"{label}: exporter resident memory", rss / 1e6, "MB"),
    ]


def main() -> None:
    """Measure the target fleet (1,000 x 50) unless told otherwise."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--robots", type=int, default=1000)
    parser.add_argument("--components", type=int, default=50)
    parser.add_argument("--seconds", type=float, default=30)
    options = parser.parse_args()
    emit(run(options.robots, options.components, options.seconds))


if __name__ == "__main__":
    main()
