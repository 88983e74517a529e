"""Alert rules at fleet scale: a real Prometheus runs the shipped rules of both profiles against a fleet.

1,000 robots x 50 components (3 WARN and 2 ERROR leaves a robot, plus their groups: every robot in ERROR)
publish over loopback DDS to one exporter. For each profile Debian's Prometheus loads the shipped config and
rules and sends to Debian's Alertmanager with the shipped example, whose receivers post to a local webhook.
First the shipped rules run alone (the target rows); then, in the same Prometheus, a copy of every group with
the same expressions and no annotations joins them (the floor: what the alerts cost without their texts).

Prometheus reports, per group, the duration of its last evaluation and its missed iterations; the rows give
the median and the worst of them over each phase as a share of the group's interval.

    python -m bench.bench_alert_rules                # 1,000 robots (make bench)
    python -m bench.bench_alert_rules --robots 3000  # run it under flock /tmp/overseer-bench.lock
"""

from __future__ import annotations

import argparse
import os
import re
import signal
import statistics
import sys
import tempfile
import time
import urllib.request
from collections.abc import Iterator
from contextlib import ExitStack, contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import yaml

from bench.common import Row, emit, tree_cpu_seconds

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
from testbed.alertmanager import Alertmanager, example_config, running_alertmanager
from testbed.ports import fresh_domain_id
from testbed.processes import Exporter, running_exporter, running_simulator, wait_for
from testbed.prometheus import Prometheus, parse_duration, running_prometheus, shipped_config
from testbed.webhook import WebhookReceiver, running_webhook

COMPONENTS, WARN, ERROR = 50, 3, 2
SIMULATOR_ROBOTS = 1500  # robots per simulator process, so that each keeps its 1 Hz
PROFILES = {"default": "prometheus.yml", "fast": "prometheus-fast.yml"}
TARGET_SHARE = 10.0  # per cent of the group's interval
FLOOR_PREFIX = "floor_"
MACHINE = "the machine, every process"
_GROUP_METRIC = re.compile(
    r'^(prometheus_rule_group_\w+)\{rule_group="[^;"]*;([^"]+)"\} (\S+)$', re.MULTILINE
)


@dataclass(frozen=True)
class Phase:
    """Each group's last durations over a phase (one per evaluation), interval and missed iterations."""

    durations: dict[str, list[float]]
    intervals: dict[str, float]
    missed: dict[str, float]


def group_metrics(prometheus: Prometheus) -> dict[str, dict[str, float]]:
    """Prometheus' own prometheus_rule_group_* gauges and counters, by group name."""
    with urllib.request.urlopen(prometheus.url + "/metrics", timeout=10) as response:
        text = response.read().decode()
    found: dict[str, dict[str, float]] = {}
    for metric, group, value in _GROUP_METRIC.findall(text):
        found.setdefault(group, {})[metric.removeprefix("prometheus_rule_group_")] = float(value)
    return found


def observe(prometheus: Prometheus, seconds: float) -> Phase:
    """Collect every group's duration once per evaluation for `seconds`."""
    start = group_metrics(prometheus)
    seen: dict[str, float] = {}
    durations: dict[str, list[float]] = {}
    deadline = time.monotonic() + seconds
    latest = start
    while time.monotonic() < deadline:
        latest = group_metrics(prometheus)
        for group, values in latest.items():
            evaluated = values.get("last_evaluation_timestamp_seconds", 0.0)
            if evaluated and seen.get(group) != evaluated:
                if group in seen:  # the first reading may be from before the phase
                    durations.setdefault(group, []).append(values["last_duration_seconds"])
                seen[group] = evaluated
        time.sleep(0.5)
    missed = {
        group: values.get("iterations_missed_total", 0.0)
        - start.get(group, {}).get("iterations_missed_total", 0.0)
        for group, values in latest.items()
    }
    intervals = {group: values["interval_seconds"] for group, values in latest.items()}
    return Phase(durations, intervals, missed)


def renamed_rules(
    rule_file: Path, destination: Path, prefix: str, alert_prefix: str, *, annotations: bool
) -> Path:
    """The rule file with its groups, alerts and recording rules renamed, to load beside the original.

    Groups and recording rules (and every expression reading them) take `prefix`, alerts `alert_prefix`;
    `annotations` False leaves the alerts without theirs.
    """
    document: dict[str, Any] = yaml.safe_load(rule_file.read_text(encoding="utf-8"))
    records = {rule["record"] for group in document["groups"] for rule in group["rules"] if "record" in rule}
    for group in document["groups"]:
        group["name"] = prefix + group["name"]
        for rule in group["rules"]:
            for record in records:
                rule["expr"] = re.sub(
                    rf"(?<![\w:]){re.escape(record)}(?![\w:])", prefix + record, rule["expr"]
                )
            if "record" in rule:
                rule["record"] = prefix + rule["record"]
            else:
                rule["alert"] = alert_prefix + rule["alert"]
                if not annotations:
                    rule.pop("annotations", None)
    destination.write_text(yaml.safe_dump(document, sort_keys=False), encoding="utf-8")
    return destination


def floor_rules(rule_file: Path, destination: Path) -> Path:
    """The rule file's groups with no annotations, their groups, alerts and recording rules renamed."""
    return renamed_rules(rule_file, destination, FLOOR_PREFIX, "Floor", annotations=False)


@dataclass(frozen=True)
class Fleet:
    """The exporter and the simulator processes publishing to it."""

    exporter: Exporter
    simulator_pids: tuple[int, ...]


@contextmanager
def running_fleet(tmp: Path, robots: int) -> Iterator[Fleet]:
    """An exporter following `robots` simulated robots over loopback DDS, once every robot is up."""
    domain = fresh_domain_id()
    with ExitStack() as stack:
        exporter = stack.enter_context(running_exporter(tmp, domain, "--log.level=warning"))
        simulators = []
        for index, first in enumerate(range(0, robots, SIMULATOR_ROBOTS)):
            share = min(SIMULATOR_ROBOTS, robots - first)
            simulator = stack.enter_context(
                running_simulator(
                    tmp,
                    domain,
                    f"--robots={share}",
                    f"--namespace-prefix=s{index}/robot",
                    f"--components={COMPONENTS}",
                    f"--warn={WARN}",
                    f"--error={ERROR}",
                    "--log.level=warning",
                )
            )
            simulators.append(simulator.process.pid)

        def every_robot_up() -> bool:
            listed = exporter.get_json("/api/v1/robots")["robots"]
            return sum(1 for robot in listed if robot["up"]) == robots

        wait_for(every_robot_up, 900, interval=5.0, message=f"{robots} robots up")
        yield Fleet(exporter, tuple(simulators))


def machine_cpu_seconds() -> tuple[float, float]:
    """CPU time of the whole machine so far: busy (every state but idle and iowait), and all."""
    fields = [int(value) for value in Path("/proc/stat").read_text().split("\n", 1)[0].split()[1:]]
    ticks = os.sysconf("SC_CLK_TCK")
    busy = sum(fields) - fields[3] - fields[4]
    return busy / ticks, sum(fields) / ticks


class CpuMeter:
    """CPU time of named process trees, and of the whole machine, between `start` and `stop`."""

    def __init__(self, pids: dict[str, tuple[int, ...]]) -> None:
        self._pids = pids
        self._started: dict[str, float] = {}
        self._machine = (0.0, 0.0)
        self._wall = 0.0

    def _readings(self) -> dict[str, float]:
        return {name: sum(tree_cpu_seconds(pid) for pid in pids) for name, pids in self._pids.items()}

    def start(self) -> None:
        self._started, self._machine, self._wall = self._readings(), machine_cpu_seconds(), time.monotonic()

    def stop(self) -> dict[str, float]:
        """Each tree's share of one core over the phase (%), and the machine's busy share of all its cores."""
        wall = time.monotonic() - self._wall
        now = self._readings()
        busy, total = machine_cpu_seconds()
        shares = {name: 100 * (now[name] - self._started[name]) / wall for name in self._pids}
        shares[MACHINE] = 100 * (busy - self._machine[0]) / (total - self._machine[1])
        return shares


def notifications_sent(alertmanager: Alertmanager) -> float:
    """Alertmanager's notifications_total over every integration."""
    with urllib.request.urlopen(alertmanager.url + "/metrics", timeout=10) as response:
        text = response.read().decode()
    return sum(
        float(line.rsplit(" ", 1)[1])
        for line in text.splitlines()
        if line.startswith("alertmanager_notifications_total{")
    )


@dataclass(frozen=True)
class ScrapeHealth:
    """The exporter's scrapes over a phase: their durations as Prometheus recorded them, and the failed."""

    median: float
    slowest: float
    scrapes: int
    failed: int


def scrape_health(prometheus: Prometheus, seconds: float) -> ScrapeHealth:
    """The scrapes of the exporter over the last `seconds`."""
    window = f"{seconds:.0f}s"
    (durations,) = prometheus.query(f'scrape_duration_seconds{{job="overseer"}}[{window}]')
    (ups,) = prometheus.query(f'up{{job="overseer"}}[{window}]')
    values = [float(value) for _, value in durations["values"]]
    return ScrapeHealth(
        statistics.median(values),
        max(values),
        len(values),
        sum(1 for _, value in ups["values"] if float(value) == 0),
    )


def alert_counts(prometheus: Prometheus, left_out: str = "Floor") -> dict[str, int]:
    """Prometheus' alerts now by state, those named `left_out`… (the floor's) left out."""
    counts: dict[str, int] = {}
    for alert in prometheus.alerts():
        if not alert["labels"]["alertname"].startswith(left_out):
            counts[alert["state"]] = counts.get(alert["state"], 0) + 1
    return counts


def median_share(phase: Phase, group: str) -> float:
    """The group's median evaluation time over the phase, in per cent of its interval."""
    return 100 * statistics.median(phase.durations[group]) / phase.intervals[group]


def target_rows(label: str, phase: Phase) -> list[Row]:
    """Each group's median and worst duration in per cent of its interval, and its missed iterations."""
    rows = []
    for group in sorted(group for group in phase.durations if phase.durations[group]):
        interval = phase.intervals[group]
        name = f"{label}: {group} ({interval:.0f}s)"
        median = median_share(phase, group)
        worst = 100 * max(phase.durations[group]) / interval
        missed = phase.missed.get(group, 0.0)
        rows += [
            Row(
                "alert rules",
                f"{name}: median",
                median,
                "% of interval",
                f"<= {TARGET_SHARE:.0f}",
                median <= 10,
            ),
            Row("alert rules", f"{name}: worst of {len(phase.durations[group])}", worst, "% of interval"),
            Row("alert rules", f"{name}: iterations missed", missed, "", "0", missed == 0),
        ]
    return rows


def floor_rows(label: str, phase: Phase) -> list[Row]:
    """Each group beside its copy with no annotations: both medians and their ratio."""
    rows = []
    for group in sorted(group for group in phase.durations if not group.startswith(FLOOR_PREFIX)):
        floor = FLOOR_PREFIX + group
        if not phase.durations[group] or not phase.durations.get(floor):
            continue
        shipped, bare = median_share(phase, group), median_share(phase, floor)
        rows += [
            Row(
                "alert rules",
                f"{label}: {group}, shipped, beside its floor: median",
                shipped,
                "% of interval",
            ),
            Row("alert rules", f"{label}: {group}, no annotations (floor): median", bare, "% of interval"),
            Row("alert rules", f"{label}: {group}, shipped / floor", shipped / bare if bare else 0.0, "x"),
        ]
    return rows


def measure_profile(
    tmp: Path, fleet: Fleet, webhook: WebhookReceiver, robots: int, profile: str, seconds: float
) -> list[Row]:
    """One profile: the shipped rules alone, then beside their floor in the same Prometheus."""
    label = f"{robots:,} robots, {profile} profile"
    exporter = fleet.exporter
    directory = tmp / profile
    directory.mkdir()
    received_before = len(webhook.alerts())
    with running_alertmanager(directory, example_config(webhook.url)) as alertmanager:
        config = shipped_config(PROFILES[profile], [exporter.url], alertmanager.url)
        timeout = parse_duration(config["global"]["scrape_timeout"])
        # The floor's alerts stay in Prometheus: only the shipped alerts reach Alertmanager.
        config["alerting"]["alert_relabel_configs"] = [
            {"source_labels": ["alertname"], "regex": "Floor.*", "action": "drop"}
        ]
        with running_prometheus(directory, config) as prometheus:
            time.sleep(90.0 if profile == "default" else 45.0)  # alerts past `for:`, first notifications out
            cpu = CpuMeter(
                {
                    "exporter (with its ingest workers)": (exporter.process.pid,),
                    "simulators": fleet.simulator_pids,
                    "Prometheus": (prometheus.process.pid,),
                    "Alertmanager": (alertmanager.process.pid,),
                }
            )
            cpu.start()
            alone = observe(prometheus, seconds)
            shares = cpu.stop()
            scrapes = scrape_health(prometheus, seconds)
            counts = alert_counts(prometheus)
            sent = notifications_sent(alertmanager)
            received = webhook.alerts()[received_before:]
            config_path = next(directory.glob("prometheus-*/prometheus.yml"))
            floor = floor_rules(Path(config["rule_files"][0]), directory / "floor.rules.yml")
            config["rule_files"].append(str(floor))
            config_path.write_text(yaml.safe_dump(config), encoding="utf-8")
            prometheus.process.send_signal(signal.SIGHUP)
            time.sleep(10)
            beside = observe(prometheus, seconds)
    robots_notified = len({alert.labels.get("robot") for alert in received if alert.status == "firing"})
    return [
        *target_rows(label, alone),
        Row("alert rules", f"{label}: median scrape of the exporter", scrapes.median, "s"),
        Row(
            "alert rules",
            f"{label}: slowest scrape of the exporter",
            scrapes.slowest,
            "s",
            f"< {timeout:.0f}",
            scrapes.slowest < timeout,
        ),
        Row(
            "alert rules",
            f"{label}: failed scrapes of the exporter, of {scrapes.scrapes}",
            scrapes.failed,
            "",
            "0",
            scrapes.failed == 0,
        ),
        *(
            Row(
                "alert rules",
                f"{label}: CPU, {name}",
                share,
                "% of its cores" if name == MACHINE else "% of a core",
            )
            for name, share in shares.items()
        ),
        Row("alert rules", f"{label}: alerts firing", counts.get("firing", 0), "alerts"),
        Row("alert rules", f"{label}: alerts pending", counts.get("pending", 0), "alerts"),
        Row("alert rules", f"{label}: Alertmanager notifications sent", sent, "notifications"),
        Row("alert rules", f"{label}: robots in the webhook's firing alerts", robots_notified, "robots"),
        *floor_rows(label, beside),
    ]


def main() -> None:
    """Measure both profiles at the fleet size asked for (1,000 robots by default)."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--robots", type=int, default=1000)
    parser.add_argument("--seconds", type=float, default=150.0, help="each phase's length")
    parser.add_argument("--profiles", default="default,fast")
    args = parser.parse_args()
    rows: list[Row] = []
    with (
        tempfile.TemporaryDirectory() as tmp_name,
        running_webhook() as webhook,
        running_fleet(Path(tmp_name), args.robots) as fleet,
    ):
        for profile in args.profiles.split(","):
            rows += measure_profile(Path(tmp_name), fleet, webhook, args.robots, profile, args.seconds)
            print(f"{profile} profile measured", file=sys.stderr, flush=True)
    emit(rows)


if __name__ == "__main__":
    main()
