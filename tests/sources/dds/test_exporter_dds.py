"""Simulator → DDS on loopback → exporter → HTTP: the fleet the exporter serves is the fleet on the wire."""

from __future__ import annotations

import subprocess
from pathlib import Path
from typing import Any

import pytest

from overseer.codec.cdr import encode_diagnostic_array
from overseer.levels import Level
from overseer.messages import DiagnosticArray, DiagnosticStatus
from overseer.simulator.design import aggregated_statuses, initial_levels, leaf_components
from testbed.dds_writer import raw_diagnostics_writer
from testbed.ports import fresh_domain_id
from testbed.processes import Exporter, running_exporter, running_simulator, wait_for

pytestmark = pytest.mark.servers  # every test here starts real servers or middleware


FAST = ("--fleet.stale-after=1s", "--fleet.robot-timeout=2s")


def levels_by_component(robot: dict[str, Any]) -> dict[str, str]:
    return {c["name"]: c["state"] for c in robot["components"]}


def robot_with(exporter: Exporter, name: str, components: int) -> dict[str, Any] | None:
    robot = exporter.robot(name)
    return robot if robot and robot["up"] and len(robot["components"]) == components else None


def test_exporter_shows_every_robot_and_component_with_exact_levels(tmp_path: Path, dds_domain: int) -> None:
    with (
        running_exporter(tmp_path, dds_domain) as exporter,
        running_simulator(tmp_path, dds_domain, "--robots=3", "--components=10", "--warn=2", "--error=1"),
    ):
        leaves = leaf_components(10)
        expected = {
            s.name: Level(s.level).name
            for s in aggregated_statuses(leaves, initial_levels(leaves, 2, 1), set())
        }
        for name in ("robot1", "robot2", "robot3"):
            robot = wait_for(
                lambda n=name: robot_with(exporter, n, 15), 30, message=f"{name} with 15 components"
            )
            assert levels_by_component(robot) == expected
            assert robot["state"] == "ERROR"
        samples = exporter.samples()
        for name in ("robot1", "robot2", "robot3"):
            assert samples["ros_diagnostics_robot_up"][(("robot", name),)] == 1
            assert samples["ros_diagnostics_robot_level"][(("robot", name),)] == 2
        levels = samples["ros_diagnostics_level"]
        assert levels[(("component", "/Camera/Cam2"), ("hardware_id", "camera2"), ("robot", "robot2"))] == 1
        assert levels[(("component", "/Laser"), ("hardware_id", ""), ("robot", "robot3"))] == 1
        assert levels[(("component", "/Temp"), ("hardware_id", ""), ("robot", "robot3"))] == 2
        voltage = (
            ("component", "/Power/Robot Battery"),
            ("hardware_id", "power1"),
            ("key", "voltage"),
            ("robot", "robot1"),
        )
        assert samples["ros_diagnostics_value"][voltage] == 12.7
        assert samples["overseer_messages_total"][(("result", "received"), ("transport", "dds"))] >= 3


def test_robot_level_follows_severity_order_not_numeric_max(tmp_path: Path, dds_domain: int) -> None:
    with (
        running_exporter(tmp_path, dds_domain, *FAST) as exporter,
        running_simulator(
            tmp_path,
            dds_domain,
            "--robots=1",
            "--components=5",
            "--warn=1",
            "--error=0",
            "--event=0:robot1:/Temp/Sensor1:STALE",
        ),
    ):
        robot = wait_for(lambda: robot_with(exporter, "robot1", 10), 30, message="robot1")
        assert levels_by_component(robot)["/Temp/Sensor1"] == "STALE"
        assert robot["state"] == "WARN"


def test_component_goes_stale_after_stale_after(tmp_path: Path, dds_domain: int) -> None:
    with (
        running_exporter(tmp_path, dds_domain, *FAST) as exporter,
        running_simulator(
            tmp_path, dds_domain, "--robots=1", "--rate=4", "--event=6:robot1:/Temp/Sensor1:silence"
        ),
    ):
        wait_for(lambda: robot_with(exporter, "robot1", 15), 30, message="robot1")

        def sensor_stale() -> dict[str, Any] | None:
            robot = exporter.robot("robot1")
            assert robot is not None
            states = levels_by_component(robot)
            return robot if states["/Temp/Sensor1"] == "STALE" else None

        robot = wait_for(sensor_stale, 30, message="/Temp/Sensor1 STALE")
        assert robot["up"] is True
        states = levels_by_component(robot)
        assert states["/Temp/Sensor2"] == "OK" and states["/Laser/Laser2"] == "ERROR"
        sensor = next(c for c in robot["components"] if c["name"] == "/Temp/Sensor1")
        assert sensor["reported_level"] == 0 and sensor["stale"] is True


def test_stopped_robot_goes_down_then_its_series_expire(tmp_path: Path, dds_domain: int) -> None:
    with (
        running_exporter(tmp_path, dds_domain, *FAST, "--fleet.expire-after=6s") as exporter,
        running_simulator(tmp_path, dds_domain, "--robots=2", "--rate=4", "--event=6:robot2:stop"),
    ):
        wait_for(lambda: robot_with(exporter, "robot2", 15), 30, message="robot2")
        robot = wait_for(
            lambda: (r := exporter.robot("robot2")) and not r["up"] and r, 30, message="robot2 down"
        )
        assert robot["state"] == "STALE"
        assert set(levels_by_component(robot).values()) == {"STALE"}
        assert exporter.samples()["ros_diagnostics_robot_up"][(("robot", "robot2"),)] == 0
        wait_for(
            lambda: 'robot="robot2"' not in exporter.get("/metrics").decode(), 30, message="robot2 expired"
        )
        assert exporter.robot("robot2") is None
        robot1 = exporter.robot("robot1")
        assert robot1 is not None and robot1["up"]


def test_stopped_robot_that_returns_is_up_again(tmp_path: Path, dds_domain: int) -> None:
    with (
        running_exporter(tmp_path, dds_domain, *FAST) as exporter,
        running_simulator(
            tmp_path, dds_domain, "--robots=1", "--rate=4", "--event=2:robot1:stop", "--event=7:robot1:start"
        ),
    ):
        wait_for(lambda: (r := exporter.robot("robot1")) and not r["up"], 30, message="robot1 down")
        robot = wait_for(lambda: robot_with(exporter, "robot1", 15), 30, message="robot1 back")
        assert robot["state"] == "ERROR"


def test_level_change_on_the_robot_reaches_metrics(tmp_path: Path, dds_domain: int) -> None:
    battery = (("component", "/Power/Robot Battery"), ("hardware_id", "power1"), ("robot", "robot1"))
    with (
        running_exporter(tmp_path, dds_domain) as exporter,
        running_simulator(
            tmp_path, dds_domain, "--robots=1", "--rate=4", "--event=6:robot1:/Power/Robot Battery:ERROR"
        ),
    ):
        wait_for(
            lambda: exporter.samples()["ros_diagnostics_level"].get(battery) == 2, 30, message="battery ERROR"
        )
        samples = exporter.samples()
        assert samples["ros_diagnostics_level_changes_total"][battery] == 1
        assert samples["ros_diagnostics_value"][(*battery[:2], ("key", "percentage"), battery[2])] == 4.0


def test_robot_started_after_the_exporter_is_discovered(tmp_path: Path, dds_domain: int) -> None:
    with running_exporter(tmp_path, dds_domain) as exporter:
        assert exporter.get_json("/api/v1/robots")["robots"] == []
        with running_simulator(tmp_path, dds_domain, "--robots=2", "--namespace-prefix=latecomer"):
            wait_for(lambda: robot_with(exporter, "latecomer2", 15), 30, message="latecomer2")
        names = [r["robot"] for r in exporter.get_json("/api/v1/robots")["robots"]]
        assert names == ["latecomer1", "latecomer2"]


def test_nested_namespace_is_kept_whole(tmp_path: Path, dds_domain: int) -> None:
    with (
        running_exporter(tmp_path, dds_domain) as exporter,
        running_simulator(tmp_path, dds_domain, "--robots=1", "--namespace-prefix=site_a/robot"),
    ):
        robot = wait_for(lambda: robot_with(exporter, "site_a/robot1", 15), 30, message="site_a/robot1")
        assert robot["robot"] == "site_a/robot1"
        assert 'robot="site_a/robot1"' in exporter.get("/metrics").decode()


def test_robots_on_their_own_domains_are_named_by_config(tmp_path: Path) -> None:
    domain = fresh_domain_id(2)
    config = tmp_path / "overseer.yml"
    config.write_text(
        "dds:\n  domains:\n"
        f"    - {{id: {domain}, robot_name: alpha}}\n"
        f"    - {{id: {domain + 1}, robot_name: beta}}\n"
    )
    with (
        running_exporter(tmp_path, None, f"--config.file={config}") as exporter,
        running_simulator(tmp_path, domain, "--robots=2", "--separate-domains"),
    ):
        wait_for(lambda: robot_with(exporter, "alpha", 15), 30, message="alpha")
        wait_for(lambda: robot_with(exporter, "beta", 15), 30, message="beta")


def test_raw_diagnostics_topic_is_followed(tmp_path: Path, dds_domain: int) -> None:
    with (
        running_exporter(tmp_path, dds_domain) as exporter,
        running_simulator(tmp_path, dds_domain, "--robots=1", "--topic=diagnostics"),
    ):
        robot = wait_for(lambda: robot_with(exporter, "robot1", 15), 30, message="robot1 on /diagnostics")
        assert robot["state"] == "ERROR"


def test_aggregated_topic_is_preferred_over_raw(tmp_path: Path, dds_domain: int) -> None:
    with (
        running_exporter(tmp_path, dds_domain) as exporter,
        running_simulator(
            tmp_path,
            dds_domain,
            "--robots=1",
            "--topic=diagnostics",
            "--components=3",
            "--warn=0",
            "--error=0",
        ),
    ):
        wait_for(lambda: robot_with(exporter, "robot1", 6), 30, message="robot1 raw")
        with running_simulator(tmp_path, dds_domain, "--robots=1", "--components=10"):
            robot = wait_for(lambda: robot_with(exporter, "robot1", 15), 30, message="robot1 aggregated only")
            topics = {c["name"] for c in robot["components"]}
            assert len(topics) == 15


def test_live_exposition_passes_promtool(tmp_path: Path, dds_domain: int) -> None:
    with (
        running_exporter(tmp_path, dds_domain) as exporter,
        running_simulator(tmp_path, dds_domain, "--robots=2", "--namespace-prefix=site_a/r"),
    ):
        wait_for(lambda: robot_with(exporter, "site_a/r2", 15), 30, message="robots")
        text = exporter.get("/metrics")
    result = subprocess.run(["promtool", "check", "metrics"], input=text, capture_output=True, timeout=60)
    assert result.returncode == 0, result.stdout.decode() + result.stderr.decode()
    assert text.count(b"ros_diagnostics_level{") == 30


def test_varying_values_reach_the_exporter(tmp_path: Path, dds_domain: int) -> None:
    voltage = (
        ("component", "/Power/Robot Battery"),
        ("hardware_id", "power1"),
        ("key", "voltage"),
        ("robot", "robot1"),
    )
    with (
        running_exporter(tmp_path, dds_domain) as exporter,
        running_simulator(tmp_path, dds_domain, "--robots=1", "--rate=5", "--vary-values"),
    ):
        first = wait_for(
            lambda: exporter.samples()["ros_diagnostics_value"].get(voltage), 30, message="voltage"
        )
        second = wait_for(
            lambda: (v := exporter.samples()["ros_diagnostics_value"][voltage]) != first and v,
            30,
            message="new voltage",
        )
    assert 12.0 <= first < 13.0 and 12.0 <= second < 13.0


def test_every_status_changes_at_every_publication_with_vary_values_all(
    tmp_path: Path, dds_domain: int
) -> None:
    def readings() -> dict[tuple[tuple[str, str], ...], float]:
        values = exporter.samples().get("ros_diagnostics_value", {})
        return {labels: value for labels, value in values.items() if ("key", "reading") in labels}

    with (
        running_exporter(tmp_path, dds_domain) as exporter,
        running_simulator(
            tmp_path, dds_domain, "--robots=2", "--components=5", "--rate=5", "--vary-values=all"
        ),
    ):
        first = wait_for(lambda: len(r := readings()) == 2 * 10 and r, 30, message="a reading per status")
        second = wait_for(
            lambda: (r := readings()) and all(r[labels] != first[labels] for labels in first) and r,
            30,
            message="every reading changed",
        )
    assert all(12.0 <= value < 13.0 for value in (*first.values(), *second.values()))


def test_best_effort_writers_are_heard_beside_reliable_ones_on_one_topic(
    tmp_path: Path, dds_domain: int
) -> None:
    """A reliable reader never matches a best-effort writer: the topic is then read best-effort."""
    reliable_statuses = (DiagnosticStatus(0, "/node_a/ok", "fine", "", ()),)
    best_effort_statuses = (DiagnosticStatus(2, "/node_b/lidar", "no scans", "", ()),)
    with (
        running_exporter(tmp_path, dds_domain, "--ingest.workers=1") as exporter,
        raw_diagnostics_writer(dds_domain, "rt/mixed/diagnostics") as reliable,
        raw_diagnostics_writer(dds_domain, "rt/mixed/diagnostics", best_effort=True) as best_effort,
        raw_diagnostics_writer(dds_domain, "rt/quick/diagnostics_agg", best_effort=True) as alone,
    ):

        def heard() -> bool:
            reliable.write(encode_diagnostic_array(DiagnosticArray(0, 0, "", reliable_statuses)))
            best_effort.write(encode_diagnostic_array(DiagnosticArray(0, 0, "", best_effort_statuses)))
            alone.write(encode_diagnostic_array(DiagnosticArray(0, 0, "", best_effort_statuses)))
            mixed, quick = exporter.robot("mixed"), exporter.robot("quick")
            names = {component["name"] for component in (mixed or {}).get("components", [])}
            return quick is not None and quick["up"] and names == {"/node_a/ok", "/node_b/lidar"}

        wait_for(heard, 30, interval=0.5, message="both writers of mixed, and quick")
    assert "best-effort, as a writer of it is" in exporter.log()


def test_a_best_effort_writer_found_before_any_reader_is_read_best_effort(
    tmp_path: Path, dds_domain: int
) -> None:
    """A writer already there when the exporter starts is discovered before the topic has a reader."""
    statuses = (DiagnosticStatus(1, "/node_c/battery", "low", "", ()),)
    with (
        raw_diagnostics_writer(dds_domain, "rt/early/diagnostics", best_effort=True) as early,
        running_exporter(tmp_path, dds_domain, "--ingest.workers=1") as exporter,
    ):

        def heard() -> bool:
            early.write(encode_diagnostic_array(DiagnosticArray(0, 0, "", statuses)))
            robot = exporter.robot("early")
            return robot is not None and robot["up"] and len(robot["components"]) == 1

        wait_for(heard, 30, interval=0.5, message="the best-effort writer that was there first")
        log = exporter.log()
    assert "reading rt/early/diagnostics on domain" in log
    assert "best-effort, as a writer of it is" in log
