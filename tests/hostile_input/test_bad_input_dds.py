"""Hostile diagnostics over real DDS: the exporter keeps serving, its exposition stays valid, drops count."""

from __future__ import annotations

import subprocess
import time
from pathlib import Path

import pytest
from prometheus_client.parser import text_string_to_metric_families

from overseer.codec.cdr import encode_diagnostic_array
from overseer.messages import DiagnosticArray, DiagnosticStatus
from testbed.dds_writer import raw_diagnostics_writer
from testbed.processes import Exporter, running_exporter, wait_for

pytestmark = pytest.mark.servers  # every test here starts real servers or middleware


HOSTILE_NAMES = ['quote"d', "back\\slash", "new\nline", "unicode ☃ 🤖 ロボット", "brace}{=,", "tab\there", ""]


def sample_value(exporter: Exporter, name: str, **labels: str) -> float | None:
    for family in text_string_to_metric_families(exporter.get("/metrics").decode()):
        for sample in family.samples:
            if sample.name == name and all(sample.labels.get(k) == v for k, v in labels.items()):
                return sample.value
    return None


def assert_promtool_accepts(exposition: bytes) -> None:
    result = subprocess.run(
        ["promtool", "check", "metrics"], input=exposition, capture_output=True, timeout=60
    )
    assert result.returncode == 0, result.stdout.decode() + result.stderr.decode()


def message(*statuses: DiagnosticStatus) -> bytes:
    return encode_diagnostic_array(DiagnosticArray(0, 0, "", statuses))


def test_hostile_names_are_served_escaped(tmp_path: Path, dds_domain: int) -> None:
    statuses = [
        DiagnosticStatus(i % 4, name, name, name, ((name, "1"),)) for i, name in enumerate(HOSTILE_NAMES)
    ]
    payload = bytearray(message(*statuses, DiagnosticStatus(0, "bad-utf8-AB", "", "", ())))
    at = payload.index(b"bad-utf8-AB") + 9
    payload[at : at + 2] = b"\xff\xfe"
    with (
        running_exporter(tmp_path, dds_domain) as exporter,
        raw_diagnostics_writer(dds_domain, "rt/hostile/diagnostics_agg") as writer,
    ):

        def publish_and_check() -> bool:
            assert writer.write(bytes(payload)) >= 0
            robot = exporter.robot("hostile")
            return robot is not None and len(robot["components"]) == len(HOSTILE_NAMES) + 1

        wait_for(publish_and_check, 30, interval=0.5, message="hostile components")
        names = {c["name"] for c in exporter.get_json("/api/v1/robots/hostile")["components"]}
        assert names == {*HOSTILE_NAMES, "bad-utf8-\ufffd\ufffd"}
        exposition = exporter.get("/metrics")
        parsed = {
            s.labels["component"]
            for f in text_string_to_metric_families(exposition.decode())
            for s in f.samples
            if s.name == "ros_diagnostics_level"
        }
        assert parsed == names
        assert_promtool_accepts(exposition)


def test_huge_arrays_and_strings_are_capped_and_counted(tmp_path: Path, dds_domain: int) -> None:
    many = message(
        *(DiagnosticStatus(0, f"/Group/Component{i}", "ok", "", (("v", str(i)),)) for i in range(10_000))
    )
    megabyte = "x" * 1_000_000
    huge_string = message(DiagnosticStatus(2, "/Huge", megabyte, "", (("k", megabyte),)))
    with (
        running_exporter(tmp_path, dds_domain, "--log.level=warning") as exporter,
        raw_diagnostics_writer(dds_domain, "rt/flood/diagnostics_agg") as flood,
        raw_diagnostics_writer(dds_domain, "rt/big/diagnostics_agg") as big,
    ):

        def publish_and_check() -> bool:
            assert flood.write(many) >= 0
            assert big.write(huge_string) >= 0
            robot = exporter.robot("big")
            return exporter.robot("flood") is not None and robot is not None and len(robot["components"]) == 1

        wait_for(publish_and_check, 30, interval=1.0, message="flood and big robots")
        flood_robot = exporter.get_json("/api/v1/robots/flood")
        assert len(flood_robot["components"]) == 1000  # the default max_components_per_robot
        big_robot = exporter.get_json("/api/v1/robots/big")
        assert len(big_robot["components"][0]["message"]) == 1024  # the default max_string_length
        assert (
            sample_value(exporter, "overseer_statuses_dropped_total", reason="component_limit") or 0
        ) >= 9000
        assert (sample_value(exporter, "overseer_strings_truncated_total") or 0) >= 2
        assert (
            sample_value(exporter, "overseer_messages_total", transport="dds", result="dropped") or 0
        ) >= 1
        started = time.monotonic()
        exposition = exporter.get("/metrics")
        assert time.monotonic() - started < 5
        assert_promtool_accepts(exposition)
        assert exporter.get("/-/healthy") == b"OK\n"
