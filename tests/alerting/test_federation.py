"""Beyond one machine: two exporter shards, a Prometheus per site, and a global one federating both.

Every robot must reach the global view exactly once, and the shipped alert rules must fire there; the
same with a Prometheus agent a site sending to one store (`remote_write`) instead of federation.
The servers run the shipped deploy/federation configs, with only targets, intervals and (for speed)
the fast rule profile swapped in.
"""

from __future__ import annotations

import subprocess
from pathlib import Path
from typing import Any

import pytest
import yaml

from overseer.model.shard import Shard
from testbed.paths import REPO
from testbed.processes import running_exporter, running_simulator, wait_for
from testbed.prometheus import Prometheus, running_agent, running_prometheus, running_store

FEDERATION = REPO / "deploy" / "federation"
FAST_RULES = REPO / "alert_rules" / "overseer-fast.rules.yml"
ROBOTS = [f"robot{i}" for i in range(1, 7)]


def shipped(name: str) -> dict[str, Any]:
    config: dict[str, Any] = yaml.safe_load((FEDERATION / name).read_text(encoding="utf-8"))
    config["global"].update(scrape_interval="1s", scrape_timeout="1s", evaluation_interval="1s")
    return config


def site_config(site: str, exporter_url: str) -> dict[str, Any]:
    config = shipped("prometheus-site.yml")
    config["global"]["external_labels"]["site"] = site
    config["scrape_configs"][0]["static_configs"] = [{"targets": [exporter_url.removeprefix("http://")]}]
    return config


def agent_config(site: str, exporter_url: str, store: Prometheus) -> dict[str, Any]:
    config = shipped("prometheus-agent.yml")
    del config["global"]["evaluation_interval"]  # an agent evaluates nothing
    config["global"]["external_labels"]["site"] = site
    config["scrape_configs"][0]["static_configs"] = [{"targets": [exporter_url.removeprefix("http://")]}]
    config["remote_write"][0]["url"] = store.url + "/api/v1/write"
    return config


def store_config() -> dict[str, Any]:
    config = shipped("prometheus-store.yml")
    config["rule_files"] = [str(FAST_RULES)]
    del config["alerting"]
    return config


def global_config(sites: list[Prometheus]) -> dict[str, Any]:
    config = shipped("prometheus-global.yml")
    config["rule_files"] = [str(FAST_RULES)]
    del config["alerting"]
    targets = [site.url.removeprefix("http://") for site in sites]
    config["scrape_configs"][0]["static_configs"] = [{"targets": targets}]
    return config


def test_shipped_federation_configs_pass_promtool() -> None:
    names = sorted(path.name for path in FEDERATION.glob("*.yml"))
    assert names == [f"prometheus-{role}.yml" for role in ("agent", "global", "site", "store")]
    for name in names:
        agent = ["--agent"] if name == "prometheus-agent.yml" else []  # what agent mode refuses, refused
        result = subprocess.run(
            ["promtool", "check", "config", *agent, name],
            cwd=FEDERATION,
            capture_output=True,
            text=True,
            timeout=60,
        )
        assert result.returncode == 0, result.stdout + result.stderr


@pytest.mark.servers
def test_global_prometheus_sees_every_robot_once_and_alerts(tmp_path: Path, dds_domain: int) -> None:
    shards = [{r for r in ROBOTS if Shard(i, 2).owns(r)} for i in range(2)]
    assert all(shards), "the fleet must span both shards"
    with (
        running_exporter(tmp_path, dds_domain, "--shard=0/2") as shard_a,
        running_exporter(tmp_path, dds_domain, "--shard=1/2") as shard_b,
        running_simulator(tmp_path, dds_domain, f"--robots={len(ROBOTS)}", "--rate=2"),
        running_prometheus(tmp_path, site_config("site-a", shard_a.url)) as site_a,
        running_prometheus(tmp_path, site_config("site-b", shard_b.url)) as site_b,
        running_prometheus(tmp_path, global_config([site_a, site_b])) as central,
    ):
        assert_every_robot_once_and_alerting(central, shards)


@pytest.mark.servers
def test_agents_send_every_robot_once_to_one_store_that_alerts(tmp_path: Path, dds_domain: int) -> None:
    shards = [{r for r in ROBOTS if Shard(i, 2).owns(r)} for i in range(2)]
    with (
        running_exporter(tmp_path, dds_domain, "--shard=0/2") as shard_a,
        running_exporter(tmp_path, dds_domain, "--shard=1/2") as shard_b,
        running_simulator(tmp_path, dds_domain, f"--robots={len(ROBOTS)}", "--rate=2"),
        running_store(tmp_path, store_config()) as store,
        running_agent(tmp_path, agent_config("site-a", shard_a.url, store)),
        running_agent(tmp_path, agent_config("site-b", shard_b.url, store)),
    ):
        assert_every_robot_once_and_alerting(store, shards)


def assert_every_robot_once_and_alerting(central: Prometheus, shards: list[set[str]]) -> None:
    """Every robot in `central` once, from the site of its shard, and RosRobotError firing for each."""

    def robots_seen() -> dict[str, list[str]] | None:
        series = central.query('ros_diagnostics_robot_up{job="overseer"} == 1')
        seen: dict[str, list[str]] = {}
        for sample in series:
            seen.setdefault(sample["metric"]["robot"], []).append(sample["metric"]["site"])
        return seen if set(seen) == set(ROBOTS) else None

    seen = wait_for(robots_seen, 60, interval=1.0, message="every robot in the global view")
    assert all(len(sites) == 1 for sites in seen.values()), seen
    assert {r for r, sites in seen.items() if sites == ["site-a"]} == shards[0]
    assert {r for r, sites in seen.items() if sites == ["site-b"]} == shards[1]
    counted = central.query('count(ros_diagnostics_level{job="overseer"})')
    assert float(counted[0]["value"][1]) == 15 * len(ROBOTS)

    def firing_error_robots() -> set[str] | None:
        robots = {
            alert["labels"]["robot"]
            for alert in central.alerts()
            if alert["labels"]["alertname"] == "RosRobotError" and alert["state"] == "firing"
        }
        return robots if robots == set(ROBOTS) else None

    wait_for(firing_error_robots, 90, interval=1.0, message="RosRobotError firing for every robot")
