"""Robots that report as real ROS 2 producers do, heard by the default DDS source and by --ros2 (and Zenoh).

The robots are `testbed/ros2/updater_robot.py` processes on the pinned Jazzy rclpy (Fast DDS), which report
as ros/diagnostics' diagnostic_updater does: on the absolute `/diagnostics` whatever their namespace, each
status named after its node, a start-up status with no hardware_id for every task added, partial arrays
from several nodes of one robot, at their own rate. Over Zenoh, `testbed/zenoh_updater.py` speaks
rmw_zenoh's protocol the same way. Each test watches the exporter over time, as an operator would.
"""

from __future__ import annotations

import sys
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import pytest

from testbed.nagios import run_check
from testbed.paths import REPO
from testbed.processes import Exporter, RunningProcess, running_exporter, spawn, wait_for
from testbed.ros2 import UPDATER_SCRIPT, ros2_environment, running_robots, start_robot
from testbed.zenoh import exporter_args, running_router

pytestmark = pytest.mark.servers

SOURCES = ("dds", "ros2")
LEVELS = {"OK": 0, "WARN": 1, "ERROR": 2, "STALE": 3}


@contextmanager
def exporter_for(tmp_path: Path, domain: int, source: str, *flags: str) -> Iterator[Exporter]:
    """The exporter following `domain` with `source` (the default DDS source or --ros2)."""
    if source == "dds":
        with running_exporter(tmp_path, domain, "--ingest.workers=1", *flags) as exporter:
            yield exporter
    else:
        with running_exporter(
            tmp_path,
            None,
            "--ros2",
            "--ingest.workers=1",
            *flags,
            env=ros2_environment(domain),
            loopback_flag=False,
        ) as exporter:
            yield exporter


def updaters(tmp_path: Path, domain: int, *robots: tuple[str, ...]) -> Any:
    """diagnostic_updater-like nodes, one per argument tuple, until the block ends."""
    return running_robots(tmp_path, domain, *robots, script=UPDATER_SCRIPT)


def components(exporter: Exporter, robot: str) -> dict[str, tuple[int, str]]:
    """Component name → (level now, hardware_id) of `robot` ({} while it is unknown)."""
    document = exporter.robot(robot)
    return (
        {}
        if document is None
        else {c["name"]: (c["level"], c["hardware_id"]) for c in document["components"]}
    )


def events(exporter: Exporter, robot: str) -> list[dict[str, Any]]:
    """The robot's events, oldest first."""
    found: list[dict[str, Any]] = exporter.get_json(f"/api/v1/events?robot={robot}&limit=1000")["events"]
    return found[::-1]


def watch(exporter: Exporter, robot: str, seconds: float) -> list[dict[str, tuple[int, str]]]:
    """The robot's components every half second for `seconds`."""
    seen = []
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline:
        seen.append(components(exporter, robot))
        time.sleep(0.5)
    return seen


@pytest.mark.parametrize("source", SOURCES)
def test_a_task_added_late_is_one_component_ok_never_a_stale_phantom(
    tmp_path: Path, dds_domain: int, source: str
) -> None:
    node = (
        "--namespace",
        "robot_b",
        "--node",
        "drive_node",
        "--hardware-id",
        "m1",
        "--task",
        "0:Motor:spinning",
    )
    with (
        exporter_for(tmp_path, dds_domain, source) as exporter,
        updaters(tmp_path, dds_domain, (*node, "--late-task", "3:0:Late task:fine")),
    ):
        expected = {"drive_node: Motor": (0, "m1"), "drive_node: Late task": (0, "m1")}
        wait_for(lambda: components(exporter, "robot_b") == expected, 30, message="both tasks, with m1")
        seen = watch(exporter, "robot_b", 8)  # past stale_after (5 s) since the start-up status
        check = run_check("--url", exporter.url, "--robot", "robot_b")
        history = events(exporter, "robot_b")
    assert all(state == expected for state in seen), seen
    assert check.state == 0 and check.output.startswith("OK - robot_b: 2 components OK"), check.output
    assert [(e["kind"], e["component"]) for e in history if e["kind"] != "level"] == [
        ("appeared", "drive_node: Motor"),
        ("robot_up", None),
        ("appeared", "drive_node: Late task"),
    ]


@pytest.mark.parametrize("source", SOURCES)
def test_a_node_restarted_while_the_exporter_listens_comes_back_as_it_was(
    tmp_path: Path, dds_domain: int, source: str
) -> None:
    node = ("--namespace", "robot_r", "--node", "driver", "--hardware-id", "d7", "--task", "1:Battery:low")
    with exporter_for(tmp_path, dds_domain, source) as exporter:
        expected = {"driver: Battery": (1, "d7")}
        first = start_robot(tmp_path, dds_domain, *node, script=UPDATER_SCRIPT)
        try:
            wait_for(lambda: components(exporter, "robot_r") == expected, 30, message="the node heard")
        finally:
            first.stop()
        wait_for(
            lambda: not (exporter.robot("robot_r") or {}).get("up"), 3, interval=0.1, message="down at once"
        )
        # The history records the down before the node returns (a loaded machine may take a moment).
        wait_for(
            lambda: any(e["kind"] == "robot_down" for e in events(exporter, "robot_r")),
            10,
            message="robot_down recorded",
        )
        with updaters(tmp_path, dds_domain, node):
            wait_for(lambda: (exporter.robot("robot_r") or {}).get("up"), 30, message="up again")
            seen = watch(exporter, "robot_r", 7)
            history = events(exporter, "robot_r")  # before this node stops: that is one more down
    # Its start-up status may say OK for a moment: one component, its hardware_id kept, never STALE.
    assert all(set(state) == {"driver: Battery"} for state in seen), seen
    assert all(
        state["driver: Battery"][1] == "d7" and state["driver: Battery"][0] in (0, 1) for state in seen
    )
    assert seen[-1] == expected
    kinds = [e["kind"] for e in history if e["kind"] in ("robot_up", "robot_down")]
    assert kinds == ["robot_up", "robot_down", "robot_up"], history
    times = [e["time"] for e in history if e["kind"] in ("robot_up", "robot_down")]
    assert times == sorted(times), history
    assert not [e for e in history if e["kind"] in ("missing", "expired")], history


@pytest.mark.parametrize("source", SOURCES)
def test_namespaced_nodes_on_the_absolute_topic_are_robots_of_their_namespaces(
    tmp_path: Path, dds_domain: int, source: str
) -> None:
    nodes = (
        ("--namespace", "robot_a", "--node", "drive", "--task", "0:Motor:ok"),
        (
            "--namespace",
            "robot_a/sensors",
            "--node",
            "lidar",
            "--task",
            "2:Scan:no scans",
            "--qos",
            "best_effort",
        ),
        ("--namespace", "robot_c", "--node", "drive", "--task", "1:Motor:warm"),
        ("--node", "host_monitor", "--task", "0:Disk:ok"),  # no namespace: the domain's robot
        (
            "--namespace",
            "robot_d",
            "--node",
            "aggregator",
            "--topic",
            "diagnostics_agg",
            "--bare",
            "--task",
            "0:/Power:ok",
        ),
    )
    with exporter_for(tmp_path, dds_domain, source) as exporter, updaters(tmp_path, dds_domain, *nodes):
        expected = {
            "robot_a": {"drive: Motor": (0, "hw0"), "lidar: Scan": (2, "hw0")},
            "robot_c": {"drive: Motor": (1, "hw0")},
            f"domain{dds_domain}": {"host_monitor: Disk": (0, "hw0")},
            "robot_d": {"/Power": (0, "hw0")},
        }
        wait_for(
            lambda: all(components(exporter, name) == levels for name, levels in expected.items()),
            45,
            message=f"every robot of its namespace over {source}",
        )
        robots = {robot["robot"] for robot in exporter.get_json("/api/v1/robots")["robots"]}
    assert robots == set(expected)


def test_the_robot_is_as_many_segments_of_a_nodes_namespace_as_configured(
    tmp_path: Path, dds_domain: int
) -> None:
    nodes = (
        ("--namespace", "site_a/robot7/drivers", "--node", "lidar", "--task", "0:Scan:ok"),
        ("--namespace", "site_a/robot8", "--node", "drive", "--task", "0:Motor:ok"),
    )
    with (
        exporter_for(tmp_path, dds_domain, "dds", "--fleet.robot-namespace-depth=2") as exporter,
        updaters(tmp_path, dds_domain, *nodes),
    ):
        wait_for(
            lambda: (
                {r["robot"] for r in exporter.get_json("/api/v1/robots")["robots"]}
                == {"site_a/robot7", "site_a/robot8"}
            ),
            30,
            message="robots of two segments",
        )


@pytest.mark.parametrize("source", SOURCES)
def test_nodes_sharing_a_robots_topic_give_no_missing_or_appeared_events(
    tmp_path: Path, dds_domain: int, source: str
) -> None:
    nodes = (
        ("--namespace", "robot_s", "--node", "drive", "--task", "0:Motor:ok", "--task", "0:Wheels:ok"),
        ("--namespace", "robot_s", "--node", "camera", "--task", "0:Frames:ok", "--period", "0.7"),
        (
            "--namespace",
            "robot_s",
            "--node",
            "power",
            "--task",
            "0:Battery:ok",
            "--late-task",
            "4:0:Charger:ok",
        ),
    )
    with exporter_for(tmp_path, dds_domain, source) as exporter, updaters(tmp_path, dds_domain, *nodes):
        wait_for(lambda: len(components(exporter, "robot_s")) == 5, 30, message="every node's tasks")
        seen = watch(exporter, "robot_s", 12)
        history = events(exporter, "robot_s")
    assert all(set(levels for levels, _ in state.values()) == {0} for state in seen), seen
    assert sorted(e["component"] for e in history if e["kind"] == "appeared") == [
        "camera: Frames",
        "drive: Motor",
        "drive: Wheels",
        "power: Battery",
        "power: Charger",
    ]
    assert not [e for e in history if e["kind"] in ("missing", "expired", "robot_down")], history


@pytest.mark.parametrize("source", SOURCES)
def test_a_producer_publishing_every_ten_seconds_never_goes_stale(
    tmp_path: Path, dds_domain: int, source: str
) -> None:
    # ntp_monitor when its NTP requests time out: statuses named without the node, every 10 s.
    monitor = (
        "--namespace",
        "robot_n",
        "--node",
        "NTPMonitor",
        "--bare",
        "--period",
        "10",
        "--task",
        "2:NTP offset:timeout",
    )
    with exporter_for(tmp_path, dds_domain, source) as exporter, updaters(tmp_path, dds_domain, monitor):
        wait_for(lambda: components(exporter, "robot_n").get("NTP offset") == (2, "hw0"), 30, message="heard")
        seen = watch(exporter, "robot_n", 32)  # stale_after is 5 s, robot_timeout 10 s
        document = exporter.robot("robot_n")
        history = events(exporter, "robot_n")
    assert all(state == {"NTP offset": (2, "hw0")} for state in seen), seen
    assert document is not None and document["up"] and 9.0 <= document["period"] <= 11.0
    assert document["components"][0]["stale_after"] >= 27.0
    assert not [e for e in history if e["kind"] in ("missing", "robot_down")], history


@contextmanager
def zenoh_updater(tmp_path: Path, port: int, *args: str) -> Iterator[RunningProcess]:
    """A diagnostic_updater-like node speaking rmw_zenoh's protocol, until the block ends."""
    log_path = tmp_path / f"zenoh-updater-{time.monotonic_ns()}.log"
    command = [sys.executable, "-m", "testbed.zenoh_updater", f"--port={port}", *args]
    process = RunningProcess(spawn(command, log_path, env={"PYTHONPATH": str(REPO)}), log_path)
    try:
        wait_for(lambda: "ready" in process.log(), 20, message="the node ready")
        yield process
    finally:
        process.stop()


# With two workers, robot_a is the first's and robot_d the second's: the exporter's session relays each
# sample of the one /diagnostics key to the worker of its publisher's robot.
@pytest.mark.parametrize("workers", [1, 2])
def test_zenoh_nodes_on_the_absolute_topic_are_robots_of_their_namespaces_with_one_component_per_task(
    tmp_path: Path, workers: int
) -> None:
    flag = f"--ingest.workers={workers}"
    with (
        running_router(tmp_path) as port,
        running_exporter(tmp_path, None, *exporter_args(port, flag), loopback_flag=False) as exporter,
    ):
        with (
            zenoh_updater(
                tmp_path,
                port,
                "--namespace=robot_a",
                "--node=drive",
                "--task=0:Motor:ok",
                "--late-task=3:1:Late:warm",
            ),
            zenoh_updater(tmp_path, port, "--namespace=robot_a", "--node=camera", "--task=0:Frames:ok"),
            zenoh_updater(
                tmp_path, port, "--namespace=robot_d/drivers", "--node=lidar", "--task=2:Scan:none"
            ),
        ):
            expected = {
                "robot_a": {
                    "drive: Motor": (0, "hw0"),
                    "drive: Late": (1, "hw0"),
                    "camera: Frames": (0, "hw0"),
                },
                "robot_d": {"lidar: Scan": (2, "hw0")},
            }
            wait_for(
                lambda: all(components(exporter, name) == levels for name, levels in expected.items()),
                30,
                message="robots of their nodes' namespaces over Zenoh",
            )
            seen = watch(exporter, "robot_a", 7)
            history = events(exporter, "robot_a")
            messages = exporter.samples()["overseer_messages_total"]
        robots = {robot["robot"] for robot in exporter.get_json("/api/v1/robots")["robots"]}
    assert robots == set(expected)
    assert all(state == expected["robot_a"] for state in seen), seen
    assert not [e for e in history if e["kind"] in ("missing", "expired", "robot_down")], history
    # The three nodes publish on the one key of /diagnostics, each numbering its own samples: none lost.
    assert messages[(("result", "received"), ("transport", "zenoh"))] >= 20
    assert messages[(("result", "lost"), ("transport", "zenoh"))] == 0


# A router slow to pass the token on: the exporter hears the publisher's samples, not whose they are.
@pytest.mark.parametrize("workers", [1, 2])
def test_a_zenoh_publisher_whose_token_comes_late_moves_to_its_robot_and_the_domains_robot_goes(
    tmp_path: Path, workers: int
) -> None:
    flag = f"--ingest.workers={workers}"
    expected = {"drive: Motor": (1, "hw0")}
    with (
        running_router(tmp_path) as port,
        running_exporter(tmp_path, None, *exporter_args(port, flag), loopback_flag=False) as exporter,
        zenoh_updater(
            tmp_path, port, "--namespace=robot_z", "--node=drive", "--task=1:Motor:warm", "--token-delay=8"
        ),
    ):
        wait_for(lambda: components(exporter, "domain0") == expected, 30, message="the domain's robot first")
        wait_for(
            lambda: (
                components(exporter, "robot_z") == expected
                and {robot["robot"] for robot in exporter.get_json("/api/v1/robots")["robots"]} == {"robot_z"}
            ),
            30,
            message="its node's robot alone",
        )
        wait_for(
            lambda: "reattributed" in [e["kind"] for e in events(exporter, "domain0")],
            10,
            message="the event",
        )
        forgotten = exporter.samples()["overseer_robots_forgotten_total"]
        domain_kinds = [e["kind"] for e in events(exporter, "domain0")]
        robot_kinds = [e["kind"] for e in events(exporter, "robot_z")]
    assert forgotten[(("reason", "reattributed"),)] == 1
    assert domain_kinds[-1] == "reattributed" and "robot_down" not in domain_kinds
    assert "robot_down" not in robot_kinds and "robot_up" in robot_kinds
