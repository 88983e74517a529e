"""bench_rules_at_scale's inputs: the exposition it serves, and the rules it compares beside the shipped."""

from __future__ import annotations

import re
import subprocess
from pathlib import Path

import yaml
from prometheus_client.parser import text_string_to_metric_families

from bench.bench_rules_at_scale import COMPARED_PREFIX, compared_rules, fleet_exposition
from testbed.paths import REPO
from testbed.prometheus import load_rules

SHIPPED = REPO / "alert_rules" / "overseer.rules.yml"


def test_the_exposition_has_the_robots_in_trouble_asked_for_every_component_fresh_and_no_values() -> None:
    families = {
        family.name: family for family in text_string_to_metric_families(fleet_exposition(20, 3).decode())
    }
    counts: dict[str, dict[str, float]] = {}
    for sample in families["ros_diagnostics_robot_components"].samples:
        counts.setdefault(sample.labels["robot"], {})[sample.labels["level"]] = sample.value
    assert len(counts) == 20
    in_error = {robot for robot, levels in counts.items() if levels["ERROR"]}
    assert in_error == {"site0/robot0", "site1/robot1", "site2/robot2"}
    assert {levels["STALE"] for levels in counts.values()} == {0}
    assert {sum(levels.values()) for levels in counts.values()} == {55}  # 50 leaves and their 5 groups
    assert not families["ros_diagnostics_value"].samples
    assert len(families["ros_diagnostics_level"].samples) == 20 * 55


def test_compared_rules_are_renamed_so_that_both_files_load_together(tmp_path: Path) -> None:
    compared = compared_rules(SHIPPED, tmp_path / "compared.rules.yml")
    for rule in load_rules(compared):
        name = rule.get("record") or rule["alert"]
        assert name.startswith((COMPARED_PREFIX, "Compared")), name
    records = {rule["record"] for rule in load_rules(SHIPPED) if "record" in rule}
    for rule in load_rules(compared):
        for record in records:  # every recording rule read is the compared one, never the shipped
            assert not re.search(rf"(?<![\w:]){re.escape(record)}(?![\w:])", rule["expr"]), rule["expr"]
    groups = [
        {group["name"] for group in yaml.safe_load(path.read_text())["groups"]}
        for path in (SHIPPED, compared)
    ]
    assert groups[1] == {COMPARED_PREFIX + name for name in groups[0]}
    result = subprocess.run(
        ["promtool", "check", "rules", str(SHIPPED), str(compared)],
        capture_output=True,
        text=True,
        check=False,
    )
    assert result.returncode == 0, result.stdout + result.stderr
