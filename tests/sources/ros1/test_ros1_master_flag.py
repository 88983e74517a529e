"""`overseer run --ros-master URL` alone follows a real ROS 1 master's robot, named after its host."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest
from prometheus_client.parser import text_string_to_metric_families

from testbed.nagios import run_check
from testbed.processes import Exporter, running_exporter, wait_for
from testbed.ros1 import running_master, running_publisher

pytestmark = pytest.mark.servers  # every test here starts real servers or middleware


FAST = ("--fleet.stale-after=1s", "--fleet.robot-timeout=2s")
AGGREGATOR = ("OK:/Power/Battery:Charged:bms:voltage=12.6", "WARN:/Temp/Motor:Warm:t1:temperature=71.5")


def robot_up(exporter: Exporter, name: str) -> dict[str, Any] | None:
    """The robot's API document once it is up."""
    robot = exporter.robot(name)
    return robot if robot and robot["up"] else None


def robot_names(exporter: Exporter) -> set[str]:
    """Every robot the exporter knows."""
    return {robot["robot"] for robot in exporter.get_json("/api/v1/robots")["robots"]}


def status_messages(exporter: Exporter) -> dict[tuple[str, str], str]:
    """(robot, component) → message of every ros_diagnostics_status_message series on /metrics."""
    found = {}
    for family in text_string_to_metric_families(exporter.get("/metrics").decode()):
        for sample in family.samples:
            if sample.name == "ros_diagnostics_status_message":
                found[(sample.labels["robot"], sample.labels["component"])] = sample.labels["message"]
    return found


def test_ros_master_alone_names_each_robot_after_its_master_host(tmp_path: Path, dds_domain: int) -> None:
    with (
        running_master(tmp_path) as by_address,
        running_master(tmp_path) as by_hostname,
        running_publisher(tmp_path, by_address, "aggregator_a", AGGREGATOR),
        running_publisher(tmp_path, by_hostname, "aggregator_b", AGGREGATOR[:1]),
        running_exporter(
            tmp_path,
            dds_domain,
            f"--ros-master={by_address.uri}",
            f"--ros-master=http://localhost:{by_hostname.port}",
            *FAST,
        ) as exporter,
    ):
        address = wait_for(lambda: robot_up(exporter, "127.0.0.1"), 30, message="robot 127.0.0.1 up")
        wait_for(lambda: robot_up(exporter, "localhost"), 30, message="robot localhost up")
        assert robot_names(exporter) == {"127.0.0.1", "localhost"}
        assert address["transport"] == "ros1"
        assert {c["name"]: c["state"] for c in address["components"]} == {
            "/Power/Battery": "OK",
            "/Temp/Motor": "WARN",
        }
        assert status_messages(exporter) == {("127.0.0.1", "/Temp/Motor"): "Warm"}


def test_ros1_robot_name_overrides_the_default_of_the_one_master(tmp_path: Path, dds_domain: int) -> None:
    with (
        running_master(tmp_path) as master,
        running_publisher(tmp_path, master, "aggregator", AGGREGATOR),
        running_exporter(
            tmp_path, dds_domain, f"--ros-master={master.uri}", "--ros1.robot=forklift", *FAST
        ) as exporter,
    ):
        forklift = wait_for(lambda: robot_up(exporter, "forklift"), 30, message="robot forklift up")
        assert forklift["transport"] == "ros1"
        assert robot_names(exporter) == {"forklift"}


def test_check_with_ros_master_alone_names_the_robot_as_the_exporter_does(tmp_path: Path) -> None:
    with (
        running_master(tmp_path) as master,
        running_publisher(tmp_path, master, "aggregator", AGGREGATOR),
    ):
        result = run_check("--ros-master", master.uri, "-t", "10")
    assert result.state == 1, result.output
    assert result.output.splitlines()[0].startswith("WARNING - 127.0.0.1: /Temp/Motor (Warm)"), result.output
