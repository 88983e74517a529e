"""The shipped rules at fleet size, alone: Prometheus evaluates them over a static copy of an exposition.

A fleet model of N robots x 50 components (`--trouble` of them with two ERROR and three WARN leaves, the rest
OK) is filled in this process and rendered once by the exporter's own renderer, without key-values (as
`metrics.value_keys: []`; every other family is in). Debian's Prometheus scrapes those bytes, served
static, every `--scrape-interval` with the shipped default profile's config and rules, first for
`--warm-up` seconds (15 minutes: the longest range the rules read is full from then on), then over a window
of `--seconds`: each group's median and worst evaluation time as a share of its interval (target <= 10 %),
how many evaluations that is, and the costliest rules from /api/v1/rules. No fleet, router or exporter
shares the cores: this is what the rules cost at that size (with `--compare`, beside the other rules),
where `bench_scale --rules` measures them beside the whole pipeline.

`--compare RULES_FILE` evaluates another rules file in the same Prometheus at the same time, its groups
renamed `compared_*` (say the previous release's rules, from `git show REV:alert_rules/overseer.rules.yml`):
the ratio of each shipped group to its namesake is taken in one run.

    python -m bench.bench_rules_at_scale --robots 10000 --trouble 200
"""

from __future__ import annotations

import argparse
import re
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

from bench.bench_alert_rules import PROFILES, alert_counts, median_share, observe, renamed_rules, target_rows
from bench.bench_scale import rule_times
from bench.bench_scrape import static_server
from bench.common import Row, emit
from overseer.codec.cdr import WIRE_FORMAT, encode_diagnostic_array
from overseer.fleet.exposition import FleetExposition
from overseer.ingest.payload import PayloadIngest
from overseer.messages import DiagnosticArray
from overseer.model import FleetLimits, FleetModel
from overseer.serve.assembler import ExpositionAssembler
from overseer.serve.exposition_formats import TEXT
from overseer.simulator.design import aggregated_statuses, initial_levels, leaf_components

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
from testbed.prometheus import running_prometheus, shipped_config

LEAVES, SITES = 50, 10
WARN, ERROR = 3, 2  # leaves of a robot in trouble
COMPARED_PREFIX, COMPARED_ALERT_PREFIX = "compared_", "Compared"
RULE_SHARE_SHOWN = 0.5  # per cent of the interval: cheaper rules are left out of the rows
NO_KEYS = re.compile(r"(?!)")
WARM_UP = (
    900.0  # the longest range the rules read (RosRobotFlapping's 15m): every evaluation then reads it whole
)


def fleet_exposition(robots: int, trouble: int) -> bytes:
    """The exporter's exposition of `robots` robots, the first `trouble` of them in ERROR, all fresh."""
    model = FleetModel(FleetLimits(max_robots=robots), clock=lambda: 1000.0)
    leaves = leaf_components(LEAVES)
    healthy = DiagnosticArray(
        0, 0, "", tuple(aggregated_statuses(leaves, initial_levels(leaves, 0, 0), set()))
    )
    levels = initial_levels(leaves, WARN, ERROR)
    failing = DiagnosticArray(0, 0, "", tuple(aggregated_statuses(leaves, levels, set())))
    payloads = (encode_diagnostic_array(failing), encode_diagnostic_array(healthy))
    for index in range(robots):
        name = f"site{index % SITES}/robot{index}"
        ingest = PayloadIngest(model, name, "dds", f"rt/{name}/diagnostics_agg", WIRE_FORMAT)
        ingest(payloads[index >= trouble])
    part = FleetExposition(model, NO_KEYS).render_part()
    return ExpositionAssembler(("dds",)).assemble([part])


def compared_rules(rule_file: Path, destination: Path) -> Path:
    """`rule_file` with its groups, alerts and recording rules renamed, so that it runs beside the shipped."""
    return renamed_rules(rule_file, destination, COMPARED_PREFIX, COMPARED_ALERT_PREFIX, annotations=True)


def measure(
    body: bytes, directory: Path, seconds: float, interval: int, warm_up: float, compare: Path | None
) -> tuple[list[Row], dict[str, Any]]:
    """The shipped rules (and `compare`'s) over `body` scraped every `interval`, after `warm_up` seconds."""
    with static_server(body, TEXT.content_type) as target:
        config = shipped_config(PROFILES["default"], [f"http://{target}"])
        config["global"].update(scrape_interval=f"{interval}s", scrape_timeout=f"{interval}s")
        if compare is not None:
            config["rule_files"].append(str(compared_rules(compare, directory / "compared.rules.yml")))
        with running_prometheus(directory, config) as prometheus:
            time.sleep(max(warm_up, 2 * interval))
            phase = observe(prometheus, seconds)
            counts = alert_counts(prometheus, left_out=COMPARED_ALERT_PREFIX)
            rules = rule_times(prometheus)
    rows = [
        *target_rows("rules alone", phase),
        *(
            Row("alert rules", f"rules alone: {group}, {rule}: median", share, "% of the group's interval")
            for (group, rule), share in sorted(rules.items(), key=lambda item: -item[1])
            if share >= RULE_SHARE_SHOWN
        ),
    ]
    for group in sorted(phase.durations):
        compared = COMPARED_PREFIX + group
        if group.startswith(COMPARED_PREFIX) or not phase.durations.get(compared):
            continue
        ratio = median_share(phase, group) / max(median_share(phase, compared), 1e-9)
        rows.append(Row("alert rules", f"rules alone: {group}, shipped / compared", ratio, "x"))
    return rows, counts


def main() -> None:
    """Measure the shipped rules over one fleet size."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0] if __doc__ else None)
    parser.add_argument("--robots", type=int, default=10_000)
    parser.add_argument("--trouble", type=int, default=200, help="robots in ERROR (default 200)")
    parser.add_argument("--seconds", type=float, default=600.0, help="the window observed")
    parser.add_argument(
        "--warm-up",
        type=float,
        default=WARM_UP,
        help="seconds scraped before the window (default 900: RosRobotFlapping's 15m range full)",
    )
    parser.add_argument("--scrape-interval", type=int, default=60)
    parser.add_argument("--compare", type=Path, help="another rules file, evaluated beside the shipped")
    args = parser.parse_args()
    started = time.monotonic()
    body = fleet_exposition(args.robots, args.trouble)
    samples = sum(1 for line in body.splitlines() if line and not line.startswith(b"#"))
    rows = [
        Row("alert rules", f"rules alone: {args.robots} robots x {LEAVES}, samples a scrape", samples, ""),
        Row("alert rules", "rules alone: exposition built in", time.monotonic() - started, "s"),
    ]
    with tempfile.TemporaryDirectory(prefix="overseer-rules-at-scale-") as directory:
        measured, counts = measure(
            body, Path(directory), args.seconds, args.scrape_interval, args.warm_up, args.compare
        )
    rows += measured
    pending = f"/ {counts.get('pending', 0)}"
    rows.append(
        Row("alert rules", "rules alone: shipped alerts firing / pending", counts.get("firing", 0), pending)
    )
    emit(rows)


if __name__ == "__main__":
    main()
