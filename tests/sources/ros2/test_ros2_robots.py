"""Real ROS 2 Jazzy robots (rclpy from the pinned PyPI wheels) heard by the default DDS source and by --ros2.

Every robot is a process of its own running `testbed/ros2/robot.py` on rmw_fastrtps_cpp, on a ROS domain
of the test's own with discovery kept on this host (ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST); the
exporter joins it either with Cyclone DDS on loopback (the default source) or as a ROS 2 node (--ros2).
"""

from __future__ import annotations

import signal
import time
from pathlib import Path
from typing import Any

import pytest

from overseer.codec.cdr import decode_diagnostic_array, encode_diagnostic_array
from overseer.messages import DiagnosticArray, DiagnosticStatus
from testbed.processes import Exporter, running_exporter, running_simulator, wait_for
from testbed.ros2 import graph_node, ros2_environment, running_robots, start_robot

pytestmark = pytest.mark.servers  # every test here starts real servers or middleware

SOURCES = {
    "dds": ("--ingest.workers=1",),
    "ros2": ("--ros2", "--ingest.workers=1"),
}
FAST = ("--fleet.stale-after=2s", "--fleet.robot-timeout=4s")


def exporter_for(tmp_path: Path, domain: int, source: str, *flags: str) -> Any:
    """The exporter following `domain` with `source`, its ROS environment as the robots'."""
    if source == "dds":
        return running_exporter(tmp_path, domain, *SOURCES[source], *flags)
    return running_exporter(
        tmp_path, None, *SOURCES[source], *flags, env=ros2_environment(domain), loopback_flag=False
    )


def components(exporter: Exporter, robot: str) -> dict[str, int]:
    """Component name → level of `robot` now ({} while it is unknown)."""
    document = exporter.robot(robot)
    return {} if document is None else {c["name"]: c["level"] for c in document["components"]}


@pytest.mark.parametrize("source", list(SOURCES))
def test_reliable_best_effort_nested_and_raw_robots_are_all_heard(
    tmp_path: Path, dds_domain: int, source: str
) -> None:
    robots = (
        ("--namespace", "robot1", "--status", "0:/Power/Battery:OK"),
        ("--namespace", "site_a/robot7", "--qos", "best_effort", "--status", "2:/Laser/Front:no scans"),
        ("--namespace", "robot2", "--durability", "transient_local", "--status", "1:/Motor/Left:warm"),
        # raw /diagnostics from two nodes of one robot
        ("--namespace", "robot3", "--topic", "diagnostics", "--node", "driver", "--status", "0:/driver:ok"),
        ("--namespace", "robot3", "--topic", "diagnostics", "--node", "camera", "--status", "1:/camera:dim"),
    )
    with (
        exporter_for(tmp_path, dds_domain, source) as exporter,
        running_robots(tmp_path, dds_domain, *robots),
    ):
        expected = {
            "robot1": {"/Power/Battery": 0},
            "site_a/robot7": {"/Laser/Front": 2},
            "robot2": {"/Motor/Left": 1},
            "robot3": {"/driver": 0, "/camera": 1},
        }
        wait_for(
            lambda: all(components(exporter, name) == levels for name, levels in expected.items()),
            45,
            message=f"every robot over {source}",
        )
        summary = {robot["robot"]: robot for robot in exporter.get_json("/api/v1/robots")["robots"]}
    assert set(summary) == set(expected)
    assert all(robot["up"] and robot["transport"] == source for robot in summary.values())


@pytest.mark.parametrize("source", list(SOURCES))
def test_a_robot_leaving_cleanly_is_down_at_once_and_a_killed_one_at_the_timeout(
    tmp_path: Path, dds_domain: int, source: str
) -> None:
    with exporter_for(tmp_path, dds_domain, source, *FAST) as exporter:
        leaving = start_robot(tmp_path, dds_domain, "--namespace", "leaving")
        killed = start_robot(tmp_path, dds_domain, "--namespace", "killed")
        try:
            wait_for(
                lambda: components(exporter, "leaving") and components(exporter, "killed"), 45, message="both"
            )
            left_at = time.monotonic()
            leaving.stop(signal.SIGTERM)  # the robot's node leaves the graph cleanly
            wait_for(lambda: not exporter.robot("leaving")["up"], 10, interval=0.05, message="leaving down")
            down_after = time.monotonic() - left_at
            killed.process.kill()
            killed_at = time.monotonic()
            wait_for(lambda: not exporter.robot("killed")["up"], 15, interval=0.1, message="killed down")
            killed_down_after = time.monotonic() - killed_at
        finally:
            killed.stop()
            leaving.stop()
        robot = exporter.robot("leaving")
    assert down_after < 2.0, f"down {down_after:.2f}s after a clean exit"
    assert robot["publisher_alive"] is False
    assert 2.0 < killed_down_after < 6.0  # robot_timeout (4 s), not the middleware's 20 s lease


def test_the_exporter_is_a_node_of_the_graph_and_publishes_the_fleet(tmp_path: Path, dds_domain: int) -> None:
    robots = (
        ("--namespace", "alpha", "--status", "2:/Power/Battery:critically low", "--status", "1:/Motor:warm"),
        ("--namespace", "beta", "--status", "0:/Power/Battery:OK"),
    )
    received: list[bytes] = []
    with (
        exporter_for(tmp_path, dds_domain, "ros2", *FAST) as exporter,
        running_robots(tmp_path, dds_domain, *robots),
        graph_node(dds_domain) as observer,
    ):
        from diagnostic_msgs.msg import DiagnosticArray

        observer.call(
            lambda: observer.node.create_subscription(
                DiagnosticArray, "/overseer/fleet_diagnostics", received.append, 10, raw=True
            )
        )
        wait_for(lambda: components(exporter, "alpha") and components(exporter, "beta"), 45, message="robots")
        nodes = wait_for(
            lambda: [
                name
                for name, _ in observer.call(observer.node.get_node_names_and_namespaces)
                if name == "overseer"
            ],
            15,
            message="the exporter's node in the graph",
        )
        seen = len(received)  # published since both robots are known
        wait_for(lambda: len(received) >= seen + 2, 15, message="the fleet's diagnostics")
    assert nodes == ["overseer"]
    fleet = decode_diagnostic_array(received[-1])
    statuses = {status.name: status for status in fleet.statuses}
    assert set(statuses) == {"alpha", "beta"}
    assert statuses["alpha"].level == 2 and statuses["alpha"].message == "1 error, 1 warn"
    assert statuses["beta"].level == 0 and statuses["beta"].message == "all 1 OK"
    assert statuses["alpha"].hardware_id == "alpha"
    assert ("error", "1") in statuses["alpha"].values and ("warn", "1") in statuses["alpha"].values


def test_ingest_workers_are_nodes_of_their_own_and_share_the_robots(tmp_path: Path, dds_domain: int) -> None:
    robots = tuple(("--namespace", f"w{index}", "--status", "1:/x:warn") for index in range(6))
    with (
        running_exporter(
            tmp_path,
            None,
            "--ros2",
            "--ingest.workers=2",
            env=ros2_environment(dds_domain),
            loopback_flag=False,
        ) as exporter,
        running_robots(tmp_path, dds_domain, *robots),
        graph_node(dds_domain) as observer,
    ):
        wait_for(
            lambda: len(exporter.get_json("/api/v1/robots")["robots"]) == len(robots),
            45,
            message="all robots",
        )
        exporter_nodes = {"overseer", "overseer_ingest_0", "overseer_ingest_1"}

        def graph_has_every_exporter_node() -> bool:
            # The observer learns the graph by discovery too: a node may reach it after the robots did.
            names = {name for name, _ in observer.call(observer.node.get_node_names_and_namespaces)}
            return exporter_nodes <= names

        wait_for(graph_has_every_exporter_node, 30, message=f"nodes {sorted(exporter_nodes)} in the graph")
        robots_seen = [robot["robot"] for robot in exporter.get_json("/api/v1/robots")["robots"]]
    assert sorted(robots_seen) == sorted(f"w{index}" for index in range(6))  # each once


def test_garbage_hostile_names_and_the_caps_hold_over_ros2(tmp_path: Path, dds_domain: int) -> None:
    """What the DDS source guarantees holds with --ros2: counted, escaped, capped, never fatal."""
    hostile = ['quote"d', "back\\slash", "new\nline", "unicode ☃ 🤖", "brace}{=,"]
    good = encode_diagnostic_array(
        DiagnosticArray(
            0, 0, "", tuple(DiagnosticStatus(2, name, name, name, ((name, "1"),)) for name in hostile)
        )
    )
    garbage = b"\x00\x01\x00\x00" + b"\xff" * 13  # a CDR header, then a length no payload holds
    config = tmp_path / "overseer.yml"
    config.write_text("fleet:\n  max_robots: 3\n", encoding="utf-8")
    with (
        exporter_for(tmp_path, dds_domain, "ros2", f"--config.file={config}") as exporter,
        graph_node(dds_domain, "hostile_robots") as robots,
    ):
        from diagnostic_msgs.msg import DiagnosticArray as RosDiagnosticArray

        def publishers(*names: str) -> list[Any]:
            return robots.call(
                lambda: [
                    robots.node.create_publisher(RosDiagnosticArray, f"/{name}/diagnostics_agg", 10)
                    for name in names
                ]
            )

        first = publishers("hostile", "garbage")

        def decode_errors() -> float:
            counts = exporter.samples()["overseer_messages_total"]
            return float(counts.get((("result", "decode_error"), ("transport", "ros2")), 0.0))

        def publish_and_check() -> bool:
            first[0].publish(good)
            first[1].publish(garbage)
            return exporter.robot("hostile") is not None and decode_errors() > 0

        wait_for(publish_and_check, 45, interval=0.3, message="hostile names served, garbage counted")
        beyond = publishers("late1", "late2")  # one of them is beyond the cap of 3 robots

        def capped() -> bool:
            for publisher in beyond:
                publisher.publish(good)
            dropped = exporter.samples()["overseer_statuses_dropped_total"][(("reason", "robot_limit"),)]
            return dropped >= 1 and len(exporter.get_json("/api/v1/robots")["robots"]) == 3

        wait_for(capped, 30, interval=0.3, message="the robot cap applied and counted")
        names = {component["name"] for component in exporter.robot("hostile")["components"]}
        metrics = exporter.get("/metrics")
        assert exporter.get("/-/healthy") == b"OK\n"
    assert names == set(hostile)
    assert b'component="new\\nline"' in metrics and b'robot="hostile"' in metrics


@pytest.mark.parametrize(("source", "qos"), [("ros2", "reliable"), ("dds", "best_effort")])
def test_the_simulator_publishes_a_fleet_of_rclpy_robots(
    tmp_path: Path, dds_domain: int, source: str, qos: str
) -> None:
    flags = (
        "--robots=4",
        "--components=10",
        "--namespace-prefix=site_b/sim",
        "--transport=ros2",
        f"--ros2.qos={qos}",
        "--event=12:site_b/sim2:stop",  # after discovery, slow under load, and a 1 Hz array
    )
    with (
        exporter_for(tmp_path, dds_domain, source, *FAST) as exporter,
        running_simulator(tmp_path, dds_domain, *flags) as simulator,
    ):
        names = {f"site_b/sim{index}" for index in range(1, 5)}
        wait_for(
            lambda: (
                {robot["robot"] for robot in exporter.get_json("/api/v1/robots")["robots"]} == names
                and all(len(components(exporter, name)) == 15 for name in names)
            ),  # 10 leaves, 5 groups
            45,
            message="the simulated fleet",
        )
        wait_for(lambda: not exporter.robot("site_b/sim2")["up"], 30, message="the stopped robot down")
        assert exporter.robot("site_b/sim2")["publisher_alive"] is False  # left the graph: down at once
    assert f"ROS 2 domain {dds_domain} through rclpy ({qos})" in simulator.log()
