"""Soak: a 100-robot fleet at 1 Hz for 30 minutes (`--duration`), scraped every 5 s; memory and latency flat.

The exporter and the simulator run as processes over loopback DDS. The simulator waits for the exporter's
readers, changes voltages at every publication (--vary-values: no array repeats the one before), and reports
what it published; lost updates are that count minus the exporter's `received` counter. Every scrape is
parsed and must show every robot up and no component STALE. Memory and latency compare the run's early
part (10-25 % of the time, after warm-up) with its end (the last 15 %).

    python -m bench.bench_soak                  # the full 30 minutes
    python -m bench.bench_soak --duration 300   # a short run
"""

from __future__ import annotations

import argparse
import re
import statistics
import tempfile
import time
import urllib.request
from dataclasses import dataclass
from pathlib import Path

from bench.common import Row, emit, tree_cpu_seconds, tree_resident_bytes
from testbed.ports import fresh_domain_id
from testbed.processes import RunningProcess, overseer_command, running_exporter, spawn
from testbed.scrapes import parse_scrape

MEMORY_GROWTH_TARGET_MB = 5.0
LATENCY_GROWTH_TARGET = 1.5  # late median at most this times the early one (plus 2 ms)


@dataclass(frozen=True)
class Sample:
    """One scrape: when (seconds into the run), how long it took, and what it showed."""

    at: float
    latency: float
    resident: int
    healthy: bool
    received: float
    lost: float


def scrape(url: str, pid: int, robots: int, started: float) -> Sample:
    """Scrape /metrics once and read the exporter's memory."""
    begun = time.monotonic()
    with urllib.request.urlopen(url + "/metrics", timeout=30) as response:
        text = response.read().decode("utf-8")
    latency = time.monotonic() - begun
    shown = parse_scrape(text)
    healthy = shown.robots_up == robots and shown.stale_components == 0
    return Sample(begun - started, latency, tree_resident_bytes(pid), healthy, shown.received, shown.lost)


def window(samples: list[Sample], duration: float, start: float, end: float) -> list[Sample]:
    """The samples taken between fractions `start` and `end` of the run."""
    return [s for s in samples if start * duration <= s.at <= end * duration]


def published_count(simulator: RunningProcess) -> int:
    """What the stopped simulator says it published."""
    match = re.search(r"published (\d+) messages", simulator.log())
    if match is None:
        raise RuntimeError(f"the simulator did not report its count:\n{simulator.log()[-2000:]}")
    return int(match.group(1))


def soak(robots: int, components: int, rate: float, duration: float, interval: float) -> list[Row]:
    """Run the soak and return its rows."""
    domain = fresh_domain_id()
    with (
        tempfile.TemporaryDirectory() as tmp,
        running_exporter(Path(tmp), domain, "--log.level=warning") as exporter,
    ):
        simulate = [
            *overseer_command(),
            "simulate",
            f"--domain={domain}",
            "--dds.loopback-only",
            f"--robots={robots}",
            f"--components={components}",
            f"--rate={rate:g}",
            "--vary-values",
            "--wait-for-subscribers=120",
            f"--duration={duration:g}",
            "--log.level=warning",
        ]
        simulator = RunningProcess(spawn(simulate, Path(tmp) / "simulator.log"), Path(tmp) / "simulator.log")
        pid = exporter.process.pid
        try:
            while not scrape(exporter.url, pid, robots, time.monotonic()).healthy:
                if simulator.process.poll() is not None:
                    raise RuntimeError(f"the simulator stopped early:\n{simulator.log()[-2000:]}")
                time.sleep(0.5)
            started, cpu_before = time.monotonic(), tree_cpu_seconds(pid)
            samples = []
            while simulator.process.poll() is None:
                samples.append(scrape(exporter.url, pid, robots, started))
                time.sleep(max(0.0, started + len(samples) * interval - time.monotonic()))
            elapsed, cpu = time.monotonic() - started, tree_cpu_seconds(pid) - cpu_before
        finally:
            simulator.stop()
        published = published_count(simulator)
        deadline = time.monotonic() + 10  # the last messages may still be on their way
        while (final := scrape(exporter.url, pid, robots, started)).received < published:
            if time.monotonic() > deadline:
                break
            time.sleep(0.2)
    return rows(
        samples,
        elapsed,
        cpu,
        published,
        final,
        f"{robots} robots x {components + 5} components at {rate:g} Hz",
    )


def rows(
    samples: list[Sample], elapsed: float, cpu: float, published: int, final: Sample, label: str
) -> list[Row]:
    """The soak's figures, each held to its target."""
    early, late = window(samples, elapsed, 0.10, 0.25), window(samples, elapsed, 0.85, 1.0)
    memory_early = statistics.median(s.resident for s in early) / 1e6
    memory_late = statistics.median(s.resident for s in late) / 1e6
    latency_early = statistics.median(s.latency for s in early) * 1000
    latency_late = statistics.median(s.latency for s in late) * 1000
    latencies = sorted(s.latency * 1000 for s in samples)
    unhealthy = sum(not s.healthy for s in samples)
    lost = published - final.received + final.lost
    growth = memory_late - memory_early
    latency_target = latency_early * LATENCY_GROWTH_TARGET + 2
    return [
        Row("soak", f"{label}: duration", elapsed / 60, "min"),
        Row("soak", f"{label}: messages published", published, "messages"),
        Row(
            "soak",
            f"{label}: lost updates (published - received + dropped)",
            lost,
            "messages",
            "0",
            lost == 0,
        ),
        Row("soak", f"{label}: scrapes", len(samples), "scrapes"),
        Row(
            "soak", f"{label}: scrapes with a robot down or STALE", unhealthy, "scrapes", "0", unhealthy == 0
        ),
        Row("soak", f"{label}: exporter memory, early", memory_early, "MB"),
        Row("soak", f"{label}: exporter memory, end", memory_late, "MB"),
        Row(
            "soak",
            f"{label}: exporter memory growth",
            growth,
            "MB",
            f"<= {MEMORY_GROWTH_TARGET_MB:g}",
            growth <= MEMORY_GROWTH_TARGET_MB,
        ),
        Row("soak", f"{label}: scrape latency median, early", latency_early, "ms"),
        Row(
            "soak",
            f"{label}: scrape latency median, end",
            latency_late,
            "ms",
            f"<= {latency_target:.1f}",
            latency_late <= latency_target,
        ),
        Row("soak", f"{label}: scrape latency p99", latencies[int(0.99 * (len(latencies) - 1))], "ms"),
        Row("soak", f"{label}: scrape latency max", latencies[-1], "ms"),
        Row("soak", f"{label}: exporter CPU", cpu / elapsed * 100, "% of a core"),
    ]


def main() -> None:
    """Soak the default fleet for the default 30 minutes, or as the flags say."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--duration", type=float, default=1800, help="seconds (default 1800)")
    parser.add_argument("--robots", type=int, default=100)
    parser.add_argument("--components", type=int, default=20, help="leaves per robot, plus 5 groups")
    parser.add_argument("--rate", type=float, default=1.0, help="publications per second per robot")
    parser.add_argument("--scrape-interval", type=float, default=5.0, help="seconds between scrapes")
    options = parser.parse_args()
    emit(soak(options.robots, options.components, options.rate, options.duration, options.scrape_interval))


if __name__ == "__main__":
    main()
