"""Run every benchmark, each in a process of its own, and print one table."""

from __future__ import annotations

import datetime
import json
import os
import platform
import subprocess
import sys
from pathlib import Path

from bench.common import ROW_PREFIX, Row, print_table

BENCHMARKS = (
    "bench.bench_ingest",
    "bench.bench_fleet",
    "bench.bench_zenoh",
    "bench.bench_ros2",
    "bench.bench_live_values",
    "bench.bench_scrape",
    "bench.bench_memory",
    "bench.bench_check",
    "bench.bench_robot_side",
    "bench.bench_status_page",
    "bench.bench_events",
    "bench.bench_icinga2",
    "bench.bench_alert_rules",
    "bench.bench_inventory",
    "bench.bench_first_look",
    "bench.bench_collector",
    "bench.bench_worker_answers",
    "bench.bench_scale",
    "bench.bench_rules_at_scale",
)


def main() -> int:
    """Run the benchmarks named on the command line (all by default) and print their rows."""
    chosen = [f"bench.{name}" for name in sys.argv[1:]] or list(BENCHMARKS)
    rows: list[Row] = []
    failed = []
    for module in chosen:
        print(f"running {module} ...", file=sys.stderr, flush=True)
        result = subprocess.run([sys.executable, "-m", module], capture_output=True, text=True, timeout=1800)
        for line in result.stdout.splitlines():
            if line.startswith(ROW_PREFIX):
                rows.append(Row(**json.loads(line[len(ROW_PREFIX) :])))
        if result.returncode != 0:
            failed.append(module)
            print(result.stdout[-3000:], result.stderr[-3000:], file=sys.stderr)
    cpu = next(
        (
            line.split(":", 1)[1].strip()
            for line in Path("/proc/cpuinfo").read_text().splitlines()
            if line.startswith("model name")
        ),
        "?",
    )
    print(
        f"\nOverseer benchmarks, {datetime.date.today()}, {platform.python_implementation()} "
        f"{platform.python_version()}, {os.cpu_count()} cores ({cpu})\n"
    )
    print_table(rows)
    if failed:
        print(f"\nfailed: {', '.join(failed)}")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
