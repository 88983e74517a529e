"""The inventory in a real Icinga 2: labels as host variables, listed robots never heard DOWN, restarts.

One Icinga 2 daemon for the module with the shipped push ApiUser example; each test runs `overseer run`
with an inventory and the simulator's robots over DDS.
"""

from __future__ import annotations

import json
import os
import signal
from collections.abc import Iterator
from pathlib import Path

import pytest

from testbed.icinga2 import Icinga2, push_api_user, push_config, running_icinga2
from testbed.nagios import PluginResult
from testbed.ports import fresh_domain_id
from testbed.processes import running_exporter, running_simulator, wait_for

pytestmark = pytest.mark.servers

FAST_FLEET = ("--fleet.stale-after=1s", "--fleet.robot-timeout=2s")


@pytest.fixture(scope="module")
def icinga(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Icinga2]:
    """Icinga 2 with the push ApiUser example."""
    with running_icinga2(tmp_path_factory.mktemp("icinga2"), push_api_user()) as daemon:
        yield daemon


def with_inventory(config: Path, inventory: Path) -> Path:
    """The exporter configuration `config` with an inventory section."""
    document = json.loads(config.read_text(encoding="utf-8"))
    document["inventory"] = {"file": str(inventory)}
    config.write_text(json.dumps(document), encoding="utf-8")
    return config


def test_labels_become_host_variables_and_follow_a_reload(icinga: Icinga2, tmp_path: Path) -> None:
    domain = fresh_domain_id()
    inventory = tmp_path / "inventory.yml"
    inventory.write_text(
        "robots:\n  inv1/r1: {labels: {site: site_a, team: ops}}\n  inv1/ghost: {labels: {site: site_a}}\n",
        encoding="utf-8",
    )
    config = with_inventory(push_config(tmp_path, icinga, "labels", "2s"), inventory)
    with (
        running_exporter(tmp_path, domain, f"--config.file={config}", *FAST_FLEET) as exporter,
        running_simulator(tmp_path, domain, "--robots=1", "--namespace-prefix=inv1/r"),
    ):
        wait_for(lambda: "inv1.r1" in icinga.objects("hosts"), 60, message="the robot's host")
        wait_for(lambda: icinga.host_result("inv1.ghost") is not None, 30, message="the listed robot's host")
        hosts = icinga.objects("hosts")
        assert {key: hosts["inv1.r1"][key] for key in ("site", "team", "overseer_labels", "ros_robot")} == {
            "site": "site_a",
            "team": "ops",
            "overseer_labels": ["site", "team"],
            "ros_robot": "inv1/r1",
        }
        assert icinga.host_result("inv1.ghost") == PluginResult(
            1, "DOWN - inv1/ghost is down: listed in the inventory, never heard"
        )
        inventory.write_text("robots:\n  inv1/r1: {labels: {site: site_b}}\n", encoding="utf-8")
        os.kill(exporter.process.pid, signal.SIGHUP)
        wait_for(lambda: icinga.objects("hosts")["inv1.r1"].get("site") == "site_b", 30, message="site_b")
        variables = icinga.objects("hosts")["inv1.r1"]
        assert variables.get("team") is None and variables["overseer_labels"] == ["site"]
        wait_for(lambda: "inv1.ghost" not in icinga.objects("hosts"), 30, message="the unlisted host deleted")


def service_state(icinga: Icinga2, host: str) -> int | None:
    """The state of the robot service of `host` now, None before its first result."""
    answer = icinga.api("GET", "/v1/objects/services", {"attrs": ["last_check_result", "state", "host_name"]})
    for item in answer["results"]:
        attrs = item["attrs"]
        if attrs["host_name"] == host and item["name"].endswith("!ros-diagnostics"):
            return None if attrs["last_check_result"] is None else int(attrs["state"])
    return None


def test_a_restart_leaves_a_dead_robot_down_and_a_live_one_as_it_was(icinga: Icinga2, tmp_path: Path) -> None:
    domain = fresh_domain_id()
    # Results live for two intervals: 10 s outlast a restart on a loaded machine, so what Icinga shows
    # across it is what the exporters pushed, never the TTL's UNKNOWN.
    config = f"--config.file={push_config(tmp_path, icinga, 'restarts', '10s')}"
    database = f"--events.path={tmp_path / 'overseer-events.db'}"
    with running_simulator(tmp_path, domain, "--robots=1", "--namespace-prefix=inv2/live"):
        with running_exporter(tmp_path, domain, config, database, *FAST_FLEET):
            with running_simulator(tmp_path, domain, "--robots=1", "--namespace-prefix=inv2/dead"):
                for host in ("inv2.dead1", "inv2.live1"):
                    wait_for(lambda h=host: (icinga.host_result(h) or PluginResult(1, "")).state == 0, 60)
            wait_for(lambda: (icinga.host_result("inv2.dead1") or PluginResult(0, "")).state == 1, 30)
            live_state = service_state(icinga, "inv2.live1")
        assert live_state == 2  # the simulator's default robot: one ERROR
        with running_exporter(tmp_path, domain, config, database, *FAST_FLEET) as restarted:
            wait_for(lambda: "found 2 hosts" in restarted.log(), 30, message="the push finds its hosts")
            for _ in range(20):  # the dead host stays DOWN for the same reason; the live one's state holds
                result = icinga.host_result("inv2.dead1")
                assert result is not None and result.state == 1, result
                assert result.output.startswith("DOWN - inv2/dead1 is down: its diagnostics publisher left")
                assert service_state(icinga, "inv2.live1") == live_state
                wait_for(lambda: True, 0.5)
            assert "deleting its Icinga 2 objects" not in restarted.log()
