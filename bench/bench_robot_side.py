"""The robot's side (the paper's Table 1): a robot's CPU and traffic without and with the exporter.

The robot is the simulator publishing one robot's /diagnostics_agg (50 leaf components) at 1 Hz, as a
diagnostic aggregator does. Traffic is the loopback interface's transmitted bytes over each phase:
everything DDS sends (data, heartbeats, acknowledgements, discovery) on this machine.
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

from bench.common import Row, cpu_seconds, emit
from testbed.ports import fresh_domain_id
from testbed.processes import running_exporter, running_simulator, wait_for


def loopback_bytes_sent() -> int:
    for line in Path("/proc/net/dev").read_text().splitlines():
        name, _, counters = line.partition(":")
        if name.strip() == "lo":
            return int(counters.split()[8])
    raise RuntimeError("no loopback interface in /proc/net/dev")


def phase(pid: int, seconds: float) -> tuple[float, float]:
    """The robot's CPU (% of a core) and loopback bytes per second over `seconds`."""
    cpu, sent, started = cpu_seconds(pid), loopback_bytes_sent(), time.monotonic()
    time.sleep(seconds)
    elapsed = time.monotonic() - started
    return (cpu_seconds(pid) - cpu) / elapsed * 100, (loopback_bytes_sent() - sent) / elapsed


def main() -> None:
    """Measure both phases and print the rows."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=30)
    options = parser.parse_args()
    domain = fresh_domain_id()
    with (
        tempfile.TemporaryDirectory() as tmp,
        running_simulator(Path(tmp), domain, "--robots=1", "--components=50") as robot,
    ):
        time.sleep(3)  # past start-up
        cpu_off, bytes_off = phase(robot.process.pid, options.seconds)
        with running_exporter(Path(tmp), domain, "--log.level=warning") as exporter:
            wait_for(lambda: exporter.robot("robot1"), 30, message="robot1 followed")
            time.sleep(2)
            cpu_on, bytes_on = phase(robot.process.pid, options.seconds)
    emit(
        [
            Row("robot side", "robot CPU, monitoring off", cpu_off, "% of a core"),
            Row("robot side", "robot CPU, exporter subscribed", cpu_on, "% of a core"),
            Row(
                "robot side", "robot CPU change", cpu_on - cpu_off, "points", "< 1", abs(cpu_on - cpu_off) < 1
            ),
            Row("robot side", "loopback traffic, monitoring off", bytes_off / 1000, "kB/s"),
            Row("robot side", "loopback traffic, exporter subscribed", bytes_on / 1000, "kB/s"),
        ]
    )


if __name__ == "__main__":
    main()
