"""Icinga 2's CPU with active checks of check_ros_diagnostics versus results pushed by the exporter.

The paper's case, 100 robots x 10 services (the robot's overall service and 9 subsystem services), in
one run: first Icinga 2 runs `check_ros_diagnostics` for every service every `--interval` (60 s, as in
the paper), then a fresh Icinga 2 receives the same services' results pushed by the exporter every
`--interval` (and would at once on a change; the fleet does not change here, which is the poll's best
case: a poll costs the same whether anything changed or not). Each phase is measured over `--seconds`
(120 s, two intervals) after a warm-up; the push phase after every object is registered.

Figures: CPU of the icinga2 processes themselves (utime + stime from /proc/<pid>/stat), and with the
check plugins they forked and reaped (cutime + cstime), as a share of one core; the check results Icinga
counted per minute (its CIB status), and the exporter's CPU in this process (HTTP API for the checks, or
the push). `--robots 100,1000` adds ten times the paper's fleet; on a small machine the active case at
1,000 robots saturates it (it then runs only part of the checks: see results per minute, and the CPU
per result), so that one is not part of `make bench`. `--push-only` leaves the active checks out (they
cannot run at 10,000 robots here), and `--package` lets the exporter's ApiUser deploy config packages, so
that a fleet first heard is registered in one stage rather than one object a call.

    python -m bench.bench_icinga2 [--robots 100[,1000]] [--interval 60] [--seconds 120] [--warmup 20]
        [--push-only] [--package]
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

from bench.common import Row, emit
from overseer.app import Exporter
from overseer.config import load_config
from overseer.messages import DiagnosticArray, DiagnosticStatus
from testbed.icinga2 import (
    PUSH_BULK_USER,
    PUSH_USER,
    Icinga2,
    push_api_user,
    push_bulk_api_user,
    push_config,
    running_icinga2,
)
from testbed.ports import free_port
from testbed.processes import wait_for

GROUPS = ("Power", "Motor", "Temp", "Laser", "Camera", "Wheel", "Arm", "Network", "Compute")
SERVICES_PER_ROBOT = 1 + len(GROUPS)
_TICKS = os.sysconf("SC_CLK_TCK")


def robot_array(index: int) -> DiagnosticArray:
    """A robot's /diagnostics_agg: two leaves per group plus the group statuses; one WARN, one ERROR."""
    statuses = []
    for number, group in enumerate(GROUPS):
        level = 2 if number == 2 and index % 3 == 0 else 1 if number == 4 else 0
        statuses.append(DiagnosticStatus(level, f"/{group}", ("OK", "Warning", "Error")[level], "", ()))
        for leaf in (1, 2):
            leaf_level = level if leaf == 1 else 0
            statuses.append(
                DiagnosticStatus(
                    leaf_level,
                    f"/{group}/{group}{leaf}",
                    f"state {leaf_level}",
                    f"{group.lower()}{leaf}",
                    (("value", str(leaf * 1.5)),),
                )
            )
    return DiagnosticArray(0, 0, "", tuple(statuses))


def exporter(overrides: dict[str, object], config_file: Path | None, robots: int) -> Exporter:
    """An in-process exporter with no transport, its model holding `robots` robots that never go stale."""
    config = load_config(
        config_file,
        {
            "dds.enabled": False,
            "web.listen_address": f"127.0.0.1:{free_port()}",
            "fleet.stale_after": "1d",
            "fleet.robot_timeout": "1d",
            "fleet.expire_after": "2d",
            "ingest.workers": 1,  # the benchmark fills the in-process model
            **overrides,
        },
    )
    running = Exporter(config)
    assert running.model is not None
    for index in range(1, robots + 1):
        running.model.apply(f"robot{index}", robot_array(index), "dds")
    return running


def icinga2_cpu(daemon: Icinga2) -> tuple[float, float]:
    """CPU seconds of the daemon's icinga2 processes: their own, and with the children they reaped."""
    own = children = 0.0
    for entry in os.listdir("/proc"):
        if not entry.isdigit():
            continue
        try:
            with open(f"/proc/{entry}/stat", encoding="ascii", errors="replace") as stat:
                head, tail = stat.read().rsplit(")", 1)
        except OSError:
            continue
        fields = tail.split()
        if head.endswith("(icinga2") and int(fields[3]) == daemon.process.pid:  # session = the daemon's
            own += (int(fields[11]) + int(fields[12])) / _TICKS
            children += (int(fields[13]) + int(fields[14])) / _TICKS
    return own, own + children


def checks_per_minute(daemon: Icinga2) -> float:
    """Service check results Icinga counted in the last minute, active and passive."""
    status = daemon.api("GET", "/v1/status/CIB", {})["results"][0]["status"]
    return float(status["active_service_checks_1min"] + status["passive_service_checks_1min"])


def measure(daemon: Icinga2, seconds: float) -> dict[str, float]:
    """Icinga's and this process's CPU over `seconds`, as shares of a core, and checks per minute."""
    own0, total0 = icinga2_cpu(daemon)
    mine0, wall0 = time.process_time(), time.monotonic()
    time.sleep(seconds)
    own1, total1 = icinga2_cpu(daemon)
    mine1, wall = time.process_time(), time.monotonic() - wall0
    return {
        "icinga2": (own1 - own0) / wall,
        "icinga2+checks": (total1 - total0) / wall,
        "exporter": (mine1 - mine0) / wall,
        "checks/min": checks_per_minute(daemon),
    }


def poll_objects(robots: int, port: int, interval: float) -> str:
    """Hosts as an operator writes them for the poll mode, the overall service and one per subsystem.

    The hosts have no vars.ros_robot, so the shipped apply rules (one-minute interval) leave them alone
    and these rules set the interval; the check then takes the host's name as the robot's.
    """
    hosts = [
        f'object Host "robot{index}" {{\n\tcheck_command = "dummy"\n\tenable_active_checks = false\n'
        f"\tvars.bench_robot = true\n\tvars.ros_diagnostics_port = {port}\n}}\n"
        for index in range(1, robots + 1)
    ]
    services = [
        f'apply Service "ros-{name}" {{\n\timport "ros-diagnostics"\n\tcheck_interval = {interval}s\n'
        f"\t{regex}\n\tassign where host.vars.bench_robot\n}}\n"
        for name, regex in [
            ("diagnostics", ""),
            # $ starts an Icinga macro: $$ is a literal one
            *((g.lower(), f'vars.ros_diagnostics_name_regex = "^/{g}(/|$$)"') for g in GROUPS),
        ]
    ]
    return "".join(hosts) + "".join(services)


def poll_phase(robots: int, options: argparse.Namespace, tmp: Path) -> dict[str, float]:
    """Icinga 2 running every service's check_ros_diagnostics every interval against the exporter."""
    running = exporter({}, None, robots)
    running.start()
    try:
        port = running.server.server_address[1]
        with running_icinga2(tmp / f"poll{robots}", poll_objects(robots, port, options.interval)) as daemon:
            time.sleep(options.warmup)
            return measure(daemon, options.seconds)
    finally:
        running.stop()


def push_phase(robots: int, options: argparse.Namespace, tmp: Path) -> dict[str, float]:
    """A fresh Icinga 2 receiving every robot's results pushed by the exporter every interval."""
    users = push_api_user() + push_bulk_api_user()
    with running_icinga2(tmp / f"push{robots}", users) as daemon:
        username = PUSH_BULK_USER if options.package else PUSH_USER
        config = push_config(tmp, daemon, f"bench{robots}", f"{options.interval}s", username=username)
        running = exporter({}, config, robots)
        registering = time.monotonic()
        running.start()
        try:
            push = running.icinga2_push
            assert push is not None

            def registered() -> bool:
                _, _, pending = push.stats.read()
                return pending == 0 and push.stats.read()[0]["ok"] >= robots * (SERVICES_PER_ROBOT + 1)

            wait_for(registered, timeout=7200, interval=0.5, message="every robot registered")
            took = time.monotonic() - registering
            time.sleep(options.warmup)
            figures = measure(daemon, options.seconds)
            figures["register"] = took
            failed = {k: v for k, v in push.stats.read()[0].items() if k != "ok" and v}
            assert not failed, f"pushes failed: {failed}"
            return figures
        finally:
            running.stop()


def rows_for(robots: int, options: argparse.Namespace, tmp: Path) -> list[Row]:
    """Both phases for one fleet size, and their ratios (the push's rows alone with --push-only)."""
    push = push_phase(robots, options, tmp)
    name = f"icinga2, {robots} robots x {SERVICES_PER_ROBOT} services, every {options.interval:g}s"
    name += ", config package" if options.package else ", one object a call"
    share: Callable[[float], float] = lambda value: round(100 * value, 2)  # noqa: E731
    push_rows = [
        Row(name, "push: icinga2 CPU", share(push["icinga2+checks"]), "% core"),
        Row(name, "push: exporter CPU (push loop)", share(push["exporter"]), "% core"),
        Row(name, "push: service results per minute", push["checks/min"], "/min"),
        Row(
            name,
            "push: time to register every robot and push its first results",
            round(push["register"], 1),
            "s",
        ),
    ]
    if options.push_only:
        return [*push_rows, Row(name, "push: icinga2 CPU per result", per_result(push), "ms")]
    poll = poll_phase(robots, options, tmp)
    return [
        Row(name, "active checks: icinga2 CPU, own", share(poll["icinga2"]), "% core"),
        Row(
            name, "active checks: icinga2 CPU with its check plugins", share(poll["icinga2+checks"]), "% core"
        ),
        Row(name, "active checks: exporter CPU (API for the checks)", share(poll["exporter"]), "% core"),
        Row(name, "active checks: service results per minute", poll["checks/min"], "/min"),
        *push_rows,
        Row(
            name,
            "icinga2 CPU, active checks with plugins / push",
            round(poll["icinga2+checks"] / max(push["icinga2+checks"], 1e-9), 1),
            "x",
            "push < active",
            push["icinga2+checks"] < poll["icinga2+checks"],
        ),
        Row(
            name,
            "icinga2 own CPU, active / push",
            round(poll["icinga2"] / max(push["icinga2+checks"], 1e-9), 1),
            "x",
        ),
        # Per result: where the machine cannot run every active check in time, totals understate the poll.
        Row(name, "active checks: icinga2 CPU with plugins per result", per_result(poll), "ms"),
        Row(name, "push: icinga2 CPU per result", per_result(push), "ms"),
        Row(
            name,
            "icinga2 CPU per result, active checks with plugins / push",
            round(per_result(poll) / max(per_result(push), 1e-9), 1),
            "x",
        ),
    ]


def per_result(figures: dict[str, float]) -> float:
    """Icinga's CPU milliseconds (with its plugins) per service result it counted."""
    return round(1000 * figures["icinga2+checks"] * 60 / max(figures["checks/min"], 1.0), 2)


def main() -> None:
    """Parse the options, run both modes for every fleet size and print the table."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--robots", default="100", help="fleet sizes, comma-separated (default 100)")
    parser.add_argument(
        "--interval", type=float, default=60.0, help="check and push interval, s (default 60)"
    )
    parser.add_argument("--seconds", type=float, default=120.0, help="measurement window, s (default 120)")
    parser.add_argument("--warmup", type=float, default=20.0, help="wait before measuring, s (default 20)")
    parser.add_argument("--push-only", action="store_true", help="measure the push alone, not active checks")
    parser.add_argument(
        "--package", action="store_true", help="the exporter's ApiUser may deploy config packages"
    )
    options = parser.parse_args()
    rows: list[Row] = []
    with tempfile.TemporaryDirectory(prefix="bench-icinga2-") as tmp:
        for robots in (int(text) for text in options.robots.split(",")):
            rows.extend(rows_for(robots, options, Path(tmp)))
    emit(rows)


if __name__ == "__main__":
    main()
