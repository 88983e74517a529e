"""Another vendor's DDS: a Fast DDS publisher (as a Jazzy robot on rmw_fastrtps_cpp) seen by the exporter.

Fast DDS matches readers and writers by type name only, so this is the test that fails when a type
name is wrong, which Cyclone-to-Cyclone tests cannot catch.
"""

from __future__ import annotations

import re
import subprocess
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import pytest

from overseer.codec.cdr import encode_diagnostic_array
from overseer.messages import DiagnosticArray, DiagnosticStatus
from testbed.fastdds_build import build_fastdds_publisher
from testbed.paths import REPO
from testbed.processes import RunningProcess, running_exporter, spawn, wait_for

pytestmark = pytest.mark.servers  # every test here starts real servers or middleware


BUILD_DIR = REPO / ".cache" / "fastdds-build"

STATUSES = [
    "0|/Power/Robot Battery|Charge OK|bms|voltage=12.6;percentage=88",
    "1|/Temp/Sensor1|Température élevée ☀|temp1|temperature=71.5",
    "2|/Camera/Cam1|No frames received|cam1|fps=0",
    "3|/Laser|Stale|",
]


@pytest.fixture(scope="session")
def fastdds_publisher() -> Path:
    """The Fast DDS publisher, built once per checkout from Debian's fastddsgen and libfastrtps-dev."""
    return build_fastdds_publisher(BUILD_DIR)


@contextmanager
def publishing(executable: Path, tmp_path: Path, domain: int, topic: str) -> Iterator[RunningProcess]:
    args = [str(executable), "--domain", str(domain), "--topic", topic, "--rate", "4"]
    for status in STATUSES:
        args += ["--status", status]
    publisher = RunningProcess(spawn(args, tmp_path / "fastdds.log"), tmp_path / "fastdds.log")
    try:
        yield publisher
    finally:
        assert publisher.stop() == 0, publisher.log()


def components(robot: dict[str, Any]) -> dict[str, tuple[str, str, str, list[dict[str, str]]]]:
    return {c["name"]: (c["state"], c["message"], c["hardware_id"], c["values"]) for c in robot["components"]}


def test_fastdds_robot_shows_up_with_exact_statuses(
    fastdds_publisher: Path, tmp_path: Path, dds_domain: int
) -> None:
    with (
        running_exporter(tmp_path, dds_domain) as exporter,
        publishing(fastdds_publisher, tmp_path, dds_domain, "rt/fastbot/diagnostics_agg"),
    ):
        robot = wait_for(
            lambda: (r := exporter.robot("fastbot")) and r["up"] and len(r["components"]) == 4 and r,
            60,
            message="fastbot's four components",
        )
    assert robot["state"] == "ERROR"
    assert components(robot) == {
        "/Power/Robot Battery": (
            "OK",
            "Charge OK",
            "bms",
            [{"key": "voltage", "value": "12.6"}, {"key": "percentage", "value": "88"}],
        ),
        "/Temp/Sensor1": ("WARN", "Température élevée ☀", "temp1", [{"key": "temperature", "value": "71.5"}]),
        "/Camera/Cam1": ("ERROR", "No frames received", "cam1", [{"key": "fps", "value": "0"}]),
        "/Laser": ("STALE", "Stale", "", []),
    }


def test_fastdds_robot_in_nested_namespace(fastdds_publisher: Path, tmp_path: Path, dds_domain: int) -> None:
    with (
        running_exporter(tmp_path, dds_domain) as exporter,
        publishing(fastdds_publisher, tmp_path, dds_domain, "rt/site_b/fastbot7/diagnostics_agg"),
    ):
        wait_for(lambda: (r := exporter.robot("site_b/fastbot7")) and r["up"], 60, message="site_b/fastbot7")
        metrics = exporter.get("/metrics").decode()
    assert 'ros_diagnostics_robot_level{robot="site_b/fastbot7"} 2.0' in metrics


def test_fastdds_robot_without_namespace_is_named_by_config(
    fastdds_publisher: Path, tmp_path: Path, dds_domain: int
) -> None:
    config = tmp_path / "overseer.yml"
    config.write_text(f"dds:\n  domains:\n    - {{id: {dds_domain}, robot_name: forklift}}\n")
    with (
        running_exporter(tmp_path, None, f"--config.file={config}") as exporter,
        publishing(fastdds_publisher, tmp_path, dds_domain, "rt/diagnostics_agg"),
    ):
        robot = wait_for(lambda: (r := exporter.robot("forklift")) and r["up"] and r, 60, message="forklift")
    assert robot["counts"] == {"ok": 1, "warn": 1, "error": 1, "stale": 1}


GARBLED = [
    "000100000102030405",  # truncated inside the header
    "000100000100000002000000ffffff7f6f6b0000",  # frame_id length runs past the payload
    "0001000000000000000000000100000000000000ffffff7f01000000",  # status count runs past the payload
    "000100000100000002000000020000006f6b000000000000",  # string without its terminating NUL
]


def test_garbled_payloads_are_counted_and_valid_ones_still_apply(
    fastdds_publisher: Path, tmp_path: Path, dds_domain: int
) -> None:
    valid = encode_diagnostic_array(
        DiagnosticArray(1, 0, "", (DiagnosticStatus(1, "/Power/Battery", "Low", "bms", ()),))
    )
    args = [
        str(fastdds_publisher),
        "--domain",
        str(dds_domain),
        "--topic",
        "rt/garbled/diagnostics_agg",
        "--rate",
        "8",
    ]
    for garbled in GARBLED:
        args += ["--raw-hex", valid.hex(), "--raw-hex", garbled]
    log = tmp_path / "fastdds-raw.log"
    with running_exporter(tmp_path, dds_domain) as exporter:
        publisher = RunningProcess(spawn(args, log), log)
        try:
            robot = wait_for(
                lambda: (r := exporter.robot("garbled")) and r["up"] and r, 60, message="garbled robot"
            )
            assert [(c["name"], c["state"]) for c in robot["components"]] == [("/Power/Battery", "WARN")]
            wait_for(
                lambda: decode_errors(exporter.get("/metrics").decode()) >= len(GARBLED),
                60,
                message="counted drops",
            )
        finally:
            publisher.stop()
        exposition = exporter.get("/metrics")
        assert exporter.get("/-/healthy") == b"OK\n"
    result = subprocess.run(
        ["promtool", "check", "metrics"], input=exposition, capture_output=True, timeout=60
    )
    assert result.returncode == 0, result.stdout.decode() + result.stderr.decode()


def decode_errors(exposition: str) -> float:
    match = re.search(r'overseer_messages_total\{result="decode_error",transport="dds"\} (\S+)', exposition)
    return float(match.group(1)) if match else 0.0
