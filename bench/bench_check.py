"""Time check_ros_diagnostics against `python -c pass` with the same interpreter, in the same run.

Target: a real check takes at most twice as long as starting Python to do nothing.

    python -m bench.bench_check [--runs 30] [--url http://127.0.0.1:9849 --robot robot1] [--domain 77]

Without --url it starts `overseer run` and `overseer simulate` (3 robots) on loopback, and stops
them at the end. The commands alternate, each run `--runs` times; the table shows medians, and the
verdict line also the ratio of the fastest runs, which load from other processes disturbs least.

Python caches compiled modules only where it may write them: an installed package has its bytecode
compiled by pip, but an editable checkout run with PYTHONDONTWRITEBYTECODE=1 compiles the check on
every start. So every command runs twice over: with bytecode cached in a private PYTHONPYCACHEPREFIX
(warmed up first; this is the figure the target is about) and with PYTHONDONTWRITEBYTECODE=1.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import socket
import statistics
import subprocess
import sys
import tempfile
import time
import urllib.request
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path

from bench.common import Row, emit

BIN = Path(sys.executable).parent
CHECK = BIN / "check_ros_diagnostics"
TARGET_RATIO = 2.0


def main() -> None:
    """Parse the options, get an exporter, time the commands and print the table."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=30, help="runs of each command (default: 30)")
    parser.add_argument("--url", help="an exporter to check (default: start one with a simulated fleet)")
    parser.add_argument("--robot", default="robot1", help="the robot to check (default: robot1)")
    parser.add_argument("--domain", type=int, default=1 + os.getpid() % 230, help="DDS domain of our fleet")
    options = parser.parse_args()
    with exporter_url(options.url, options.domain, options.robot) as url:
        report(url, options.robot, options.runs)


def report(url: str, robot: str, runs: int) -> None:
    """Time the baseline, `-V` and a real check, cached and uncached, and print medians and ratios."""
    interpreter = shebang_interpreter(CHECK)
    commands = {
        "python -c pass": [interpreter, "-c", "pass"],
        "check_ros_diagnostics -V": [str(CHECK), "-V"],
        f"check_ros_diagnostics --url … -r {robot}": [str(CHECK), "--url", url, "-r", robot],
    }
    check = list(commands)[-1]
    require_judged(commands[check], robot)
    with tempfile.TemporaryDirectory(prefix="bench-pycache-") as cache:
        cached = wall_times(commands, runs, cached_environment(cache))
    uncached = wall_times(commands, runs, {**os.environ, "PYTHONDONTWRITEBYTECODE": "1"})
    rows = []
    for label, times in (("bytecode cached", cached), ("PYTHONDONTWRITEBYTECODE", uncached)):
        for name in commands:
            rows.append(Row("check", f"{name}, {label}", median(times, name) * 1000, "ms"))
    median_ratio, fastest_ratio = ratio(cached, check, statistics.median), ratio(cached, check, min)
    rows += [
        Row(
            "check",
            "check / python -c pass, median",
            median_ratio,
            "x",
            f"<= {TARGET_RATIO:g}",
            median_ratio <= TARGET_RATIO,
        ),
        Row("check", "check / python -c pass, fastest runs", fastest_ratio, "x"),
    ]
    print(
        f"interpreter {interpreter} (Python {sys.version.split()[0]}), {runs} runs each, medians",
        file=sys.stderr,
    )
    emit(rows)


def require_judged(check: list[str], robot: str) -> None:
    """Exit unless `check` prints `robot`'s verdict: a check that could not judge it is not one to time."""
    done = subprocess.run(check, capture_output=True, text=True, check=False)
    first = done.stdout.split("\n", 1)[0]
    if done.returncode not in (0, 1, 2, 3) or not re.match(
        rf"(OK|WARNING|CRITICAL|UNKNOWN) - {re.escape(robot)}: ", first
    ):
        raise SystemExit(
            f"{' '.join(check)} did not judge {robot} (exit {done.returncode}): {first}{done.stderr}"
        )


def median(times: dict[str, list[float]], name: str) -> float:
    """The median of a command's wall times."""
    return statistics.median(times[name])


def ratio(times: dict[str, list[float]], name: str, pick: Callable[[list[float]], float]) -> float:
    """`pick` (median or min) of a command's times over the same of `python -c pass`."""
    return pick(times[name]) / pick(times["python -c pass"])


def cached_environment(cache: str) -> dict[str, str]:
    """The environment with bytecode written to and read from the private directory `cache`."""
    environment = {key: value for key, value in os.environ.items() if key != "PYTHONDONTWRITEBYTECODE"}
    return {**environment, "PYTHONPYCACHEPREFIX": cache}


def wall_times(
    commands: dict[str, list[str]], runs: int, environment: dict[str, str]
) -> dict[str, list[float]]:
    """Wall times of each command, the commands alternating run by run after one warm-up run each."""
    times: dict[str, list[float]] = {name: [] for name in commands}
    for command in commands.values():
        run_once(command, environment)
    for _ in range(runs):
        for name, command in commands.items():
            times[name].append(run_once(command, environment))
    return times


def run_once(command: list[str], environment: dict[str, str]) -> float:
    """Wall time of one run of `command`; it must exit as a plugin does (0 to 3, UNKNOWN for -V)."""
    started = time.perf_counter()
    done = subprocess.run(command, env=environment, capture_output=True, check=False)
    elapsed = time.perf_counter() - started
    if done.returncode not in (0, 1, 2, 3) or done.stderr:
        raise SystemExit(f"{command} failed with {done.returncode}: {done.stderr.decode(errors='replace')}")
    return elapsed


def shebang_interpreter(script: Path) -> str:
    """The interpreter a console script runs with: its `#!` line."""
    first_line = script.read_text(encoding="utf-8").splitlines()[0]
    return first_line.removeprefix("#!").strip()


@contextmanager
def exporter_url(url: str | None, domain: int, robot: str) -> Iterator[str]:
    """`url`, or the URL of an exporter with a simulated fleet started for the benchmark."""
    if url:
        yield url
        return
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]
    overseer = str(BIN / "overseer")
    exporter = start(
        [
            overseer,
            "run",
            f"--web.listen-address=127.0.0.1:{port}",
            f"--dds.domain={domain}",
            "--dds.loopback-only",
        ]
    )
    simulator = start([overseer, "simulate", "--robots=3", f"--domain={domain}", "--dds.loopback-only"])
    try:
        started_url = f"http://127.0.0.1:{port}"
        wait_for_robot(started_url, robot)
        yield started_url
    finally:
        for process in (simulator, exporter):
            process.terminate()
            process.wait(30)


def start(command: list[str]) -> subprocess.Popen[bytes]:
    """Start `command` quietly."""
    return subprocess.Popen(command, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)


def wait_for_robot(url: str, robot: str, timeout: float = 60.0) -> None:
    """Wait until the exporter at `url` reports `robot` as up."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        try:
            with urllib.request.urlopen(f"{url}/api/v1/robots/{robot}", timeout=2) as response:
                if json.load(response)["up"]:
                    return
        except OSError:
            pass
        time.sleep(0.2)
    raise SystemExit(f"no robot {robot!r} at {url} after {timeout:g} s")


if __name__ == "__main__":
    main()
