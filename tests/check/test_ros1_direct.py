"""The direct ROS 1 read behind `check_ros_diagnostics --ros-master`, against a real master."""

from __future__ import annotations

import threading
import time
from pathlib import Path
from typing import Any

import pytest

from overseer.check.ros1_direct import (
    MasterUnreachableError,
    MessageTimeoutError,
    NoPublisherError,
    read_robot_document,
)
from overseer.codec.ros1 import encode_diagnostic_array
from overseer.messages import DiagnosticArray, DiagnosticStatus
from testbed.nagios import run_check
from testbed.ports import free_port
from testbed.processes import running_exporter, wait_for
from testbed.ros1 import fake_publisher, frame, kill, running_master, running_publisher, start_publisher

STATUSES = (
    "OK:/Power/Battery:Charged:bms:voltage=12.6,percent=93",
    "WARN:/Temp/Motor:Warm:t1:temperature=71.5",
    "ERROR:/Laser:No scans:hokuyo",
    "STALE:/Camera:No frames",
)
TIMES = ("generated_at", "last_message", "last_update")


def without_times(document: dict[str, Any]) -> dict[str, Any]:
    """The document with every timestamp removed, at any depth."""
    result = {k: v for k, v in document.items() if k not in TIMES}
    result["components"] = [{k: v for k, v in c.items() if k not in TIMES} for c in document["components"]]
    return result


@pytest.mark.servers
def test_direct_read_gives_what_the_exporter_serves(tmp_path: Path, dds_domain: int) -> None:
    with (
        running_master(tmp_path) as master,
        running_publisher(tmp_path, master, "aggregator", STATUSES),
        running_exporter(tmp_path, dds_domain, f"--ros1.robot=ros1a={master.uri.rstrip('/')}") as exporter,
    ):
        served = wait_for(lambda: (r := exporter.robot("ros1a")) and r["up"] and r, 30, message="ros1a up")
        direct = read_robot_document(master.uri, "ros1a", timeout=10)
        assert without_times(direct) == without_times(served)
        assert direct["state"] == "ERROR"
        assert len(direct["components"]) == 4
        assert direct["last_message"] is not None


def test_unreachable_master_fails_at_once(tmp_path: Path) -> None:
    uri = f"http://127.0.0.1:{free_port()}"
    started = time.monotonic()
    with pytest.raises(MasterUnreachableError) as raised:
        read_robot_document(uri, "r1", timeout=10)
    assert time.monotonic() - started < 2
    assert str(raised.value) == f"ROS master unreachable at {uri}: {uri} unreachable: connection refused"


@pytest.mark.servers
def test_no_publisher_fails_after_the_timeout(tmp_path: Path) -> None:
    with running_master(tmp_path) as master:
        started = time.monotonic()
        with pytest.raises(NoPublisherError) as raised:
            read_robot_document(master.uri, "r1", timeout=1.5)
        assert 1.5 <= time.monotonic() - started < 3
    assert str(raised.value) == f"no publisher of /diagnostics_agg at ROS master {master.uri} within 1.5 s"


@pytest.mark.servers
def test_publisher_that_starts_while_waiting_is_read(tmp_path: Path) -> None:
    with running_master(tmp_path) as master:
        result: list[dict[str, Any]] = []
        reader = threading.Thread(
            target=lambda: result.append(read_robot_document(master.uri, "r1", timeout=30))
        )
        reader.start()
        publisher = start_publisher(tmp_path, master, "aggregator", STATUSES)
        try:
            reader.join(30)
        finally:
            publisher.stop()
        assert result and result[0]["robot"] == "r1"


@pytest.mark.servers
def test_silent_fake_publisher_is_a_timeout(tmp_path: Path) -> None:
    with running_master(tmp_path) as master, fake_publisher(master, lambda n: [], hold_open=True):
        started = time.monotonic()
        with pytest.raises(MessageTimeoutError) as raised:
            read_robot_document(master.uri, "r1", timeout=1.5)
        assert 1.5 <= time.monotonic() - started < 3
    assert str(raised.value).startswith("timeout: no message on /diagnostics_agg within 1.5 s")


@pytest.mark.servers
def test_killed_publisher_still_listed_is_a_timeout_naming_the_refused_connection(tmp_path: Path) -> None:
    with running_master(tmp_path) as master:
        kill(start_publisher(tmp_path, master, "aggregator", STATUSES))
        assert master.publishers() == ["/aggregator"]
        with pytest.raises(MessageTimeoutError, match=r"last error: .*connection refused"):
            read_robot_document(master.uri, "r1", timeout=1.5)


@pytest.mark.servers
def test_fake_publisher_garbled_message_is_named_in_the_timeout(tmp_path: Path) -> None:
    with (
        running_master(tmp_path) as master,
        fake_publisher(master, lambda n: [frame(b"\x00" * 30)]),
        pytest.raises(MessageTimeoutError, match=r"last error: .*undecodable message: 10 bytes left over"),
    ):
        read_robot_document(master.uri, "r1", timeout=1.5)


@pytest.mark.servers
def test_fake_publisher_valid_message_is_judged_like_the_exporter_would(tmp_path: Path) -> None:
    array = DiagnosticArray(
        0, 0, "", (DiagnosticStatus(9, "/Odd", "", "", ()), DiagnosticStatus(1, "/A", "m", "", ()))
    )
    with (
        running_master(tmp_path) as master,
        fake_publisher(master, lambda n: [frame(encode_diagnostic_array(array))]),
    ):
        document = read_robot_document(master.uri, "r1", timeout=10, topic="diagnostics_agg")
    assert (document["state"], document["transport"], document["up"]) == ("WARN", "ros1", True)
    assert [c["name"] for c in document["components"]] == ["/A"]  # level 9 is no ROS level: dropped


@pytest.mark.servers
def test_failing_publisher_is_retried_at_most_twice_a_second(tmp_path: Path) -> None:
    with running_master(tmp_path) as master, fake_publisher(master, lambda n: []) as fake:
        with pytest.raises(MessageTimeoutError, match="connection closed by the publisher"):
            read_robot_document(master.uri, "r1", timeout=2)
        assert 1 <= fake.connections <= 5


@pytest.mark.servers
def test_check_with_ros_master_prints_what_the_exporter_mode_prints(tmp_path: Path, dds_domain: int) -> None:
    with (
        running_master(tmp_path) as master,
        running_publisher(tmp_path, master, "aggregator", STATUSES),
        running_exporter(tmp_path, dds_domain, f"--ros1.robot=ros1a={master.uri.rstrip('/')}") as exporter,
    ):
        wait_for(lambda: (r := exporter.robot("ros1a")) and r["up"], 30, message="ros1a up")
        for extra in ([], ["-n", "temp"], ["--perfdata-values", "-v"]):
            via_exporter = run_check("--url", exporter.url, "-r", "ros1a", *extra)
            direct = run_check("--ros-master", master.uri, "-r", "ros1a", "-t", "10", *extra)
            assert direct == via_exporter
    assert via_exporter.state == 2
    assert direct.output.startswith("CRITICAL - ros1a: /Laser (No scans)")


@pytest.mark.servers
def test_check_with_unreachable_ros_master_is_one_unknown_line() -> None:
    uri = f"http://127.0.0.1:{free_port()}"
    result = run_check("--ros-master", uri, "-r", "ros1a", "-t", "3")
    assert result.state == 3
    assert (
        result.output == f"UNKNOWN - ROS master unreachable at {uri}: {uri} unreachable: connection refused\n"
    )
