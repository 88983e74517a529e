"""The event history end to end: the real exporter and simulator over DDS, restarts, JSON logs, bad files."""

from __future__ import annotations

import json
import time
import urllib.error
from contextlib import ExitStack
from pathlib import Path
from typing import Any
from urllib.parse import urlencode

import pytest

from overseer.codec.cdr import encode_diagnostic_array
from overseer.messages import DiagnosticArray, DiagnosticStatus
from testbed.dds_writer import raw_diagnostics_writer
from testbed.processes import Exporter, running_exporter, running_simulator, wait_for

pytestmark = pytest.mark.servers  # every test here starts real servers or middleware


STALE_AFTER, ROBOT_TIMEOUT = 1.0, 2.0
FAST = (f"--fleet.stale-after={STALE_AFTER:g}s", f"--fleet.robot-timeout={ROBOT_TIMEOUT:g}s")
SCRIPT = (
    "--robots=2",
    "--components=5",
    "--warn=0",
    "--error=0",
    "--wait-for-subscribers=30",  # the script's clock starts once the exporter listens
    "--event=5:robot1:/Temp/Sensor1:ERROR",
    "--event=7:robot2:stop",
    "--event=13:robot2:start",
)


def events(exporter: Exporter, **filters: Any) -> list[dict[str, Any]]:
    document: dict[str, Any] = exporter.get_json("/api/v1/events?" + urlencode({"limit": 1000, **filters}))
    found: list[dict[str, Any]] = document["events"]
    return found


def find(exporter: Exporter, **wanted: Any) -> list[dict[str, Any]]:
    """The events whose fields have every `wanted` value."""
    return [e for e in events(exporter) if all(e[k] == v for k, v in wanted.items())]


def json_log_lines(exporter: Exporter) -> list[dict[str, Any]]:
    return [json.loads(line) for line in exporter.log().splitlines() if line.startswith("{")]


def logged_events(exporter: Exporter) -> dict[int, dict[str, Any]]:
    """The events of the exporter's JSON log lines, by id."""
    return {line["event"]["id"]: line["event"] for line in json_log_lines(exporter) if "event" in line}


def test_scripted_incidents_are_recorded_served_logged_and_kept_across_a_restart(
    tmp_path: Path, dds_domain: int
) -> None:
    database = tmp_path / "history" / "events.db"
    database.parent.mkdir()
    flags = (*FAST, f"--events.path={database}", "--log.format=json")
    with ExitStack() as stack:
        # The exporter first, so that it hears the fleet from its first message.
        exporter = stack.enter_context(running_exporter(tmp_path, dds_domain, *flags))
        stack.enter_context(running_simulator(tmp_path, dds_domain, *SCRIPT))
        error = wait_for(
            lambda: find(exporter, kind="level", robot="robot1", component="/Temp/Sensor1"),
            30,
            message="robot1's sensor going to ERROR",
        )
        assert len(error) == 1
        assert (error[0]["old_state"], error[0]["new_state"], error[0]["hardware_id"]) == (
            "OK",
            "ERROR",
            "temp1",
        )
        assert error[0]["message"] and error[0]["values"]
        down = wait_for(lambda: find(exporter, kind="robot_down", robot="robot2"), 30, message="robot2 down")
        assert down[0]["new_state"] == "STALE" and down[0]["component"] is None
        up = wait_for(
            lambda: find(exporter, kind="robot_up", robot="robot2", old_state="STALE"),
            30,
            message="robot2 up",
        )
        assert up[0]["time"] > down[0]["time"]
        # A silent robot is one robot_down, not a STALE event per component.
        assert find(exporter, robot="robot2", kind="level", new_state="STALE") == []
        assert [e["kind"] for e in events(exporter, level="ERROR", robot="robot1")] == ["level", "level"]
        before_restart = events(exporter)
        samples = exporter.samples()
        assert samples["overseer_events_written_total"][()] >= len(before_restart)
        assert samples["overseer_events_store_up"][()] == 1
        assert samples["overseer_events_database_bytes"][()] > 0
        logged = wait_for(
            lambda: (lines := logged_events(exporter)).keys() >= {e["id"] for e in before_restart} and lines,
            10,
            message="every event in the JSON log",
        )
        assert all(logged[e["id"]] == e for e in before_restart)
        assert any(line["logger"] == "overseer.app" for line in json_log_lines(exporter))

        exporter.stop()
        # Stopped for longer than robot1's timeout: the restarted exporter remembers it down, and its next
        # message is a new run (a restart within the timeout continues the run, with no event).
        time.sleep(ROBOT_TIMEOUT + 1)
        newest_before = max(e["id"] for e in before_restart)
        restarted = stack.enter_context(running_exporter(tmp_path, dds_domain, *flags))
        again_up = wait_for(
            lambda: [e for e in find(restarted, kind="robot_up", robot="robot1") if e["id"] > newest_before],
            30,
            message="robot1 up again after the restart",
        )
        assert [(e["old_state"], e["message"]) for e in again_up] == [("STALE", "diagnostics received again")]
        again = events(restarted)
        by_id = {e["id"]: e for e in again}
        assert len(by_id) == len(again)
        assert all(by_id[e["id"]] == e for e in before_restart)  # the old history, unchanged
        restarted_at = min(e["time"] for e in again if e["id"] > newest_before)
        assert all(e["time"] < restarted_at for e in before_restart)


def test_hostile_names_and_messages_over_dds_come_back_intact(tmp_path: Path, dds_domain: int) -> None:
    hostile = ['quote"d', "back\\slash", "new\nline", "unicode ☃ 🤖", "</script>", "tab\there"]
    statuses = tuple(DiagnosticStatus(2, "/" + text, text, text, ((text, text),)) for text in hostile)
    with (
        running_exporter(tmp_path, dds_domain) as exporter,  # the default database, in its working directory
        raw_diagnostics_writer(dds_domain, "rt/hostile/diagnostics_agg") as writer,
    ):
        writer.wait_for_reader()
        payload = encode_diagnostic_array(DiagnosticArray(0, 0, "", statuses))
        found = wait_for(
            lambda: (
                writer.write(payload) >= 0
                and len(appeared := find(exporter, kind="appeared")) == 6
                and appeared
            ),
            30,
            message="six hostile components",
        )
    assert (tmp_path / "overseer-events.db").stat().st_size > 0
    got = sorted((e["component"], e["hardware_id"], e["message"], e["values"], e["new_state"]) for e in found)
    want = sorted(("/" + t, t, t, [{"key": t, "value": t}], "ERROR") for t in hostile)
    assert got == want


def test_a_corrupt_database_degrades_the_exporter_without_stopping_it(
    tmp_path: Path, dds_domain: int
) -> None:
    database = tmp_path / "events.db"
    database.write_bytes(b"SQLite format 2\x00" + b"\xff" * 4096)
    with (
        running_exporter(tmp_path, dds_domain, f"--events.path={database}") as exporter,
        running_simulator(tmp_path, dds_domain, "--robots=1", "--components=3"),
    ):
        wait_for(lambda: exporter.robot("robot1"), 30, message="robot1 served all the same")
        samples = wait_for(
            lambda: (
                (s := exporter.samples())["overseer_events_dropped_total"][(("reason", "store_unavailable"),)]
                and s
            ),
            30,
            message="dropped events counted",
        )
        assert samples["overseer_events_store_up"][()] == 0
        try:
            exporter.get("/api/v1/events")
            raise AssertionError("the events answered despite an unusable database")
        except urllib.error.HTTPError as error:
            assert error.code == 503
            assert str(database) in json.loads(error.read())["error"]
        assert exporter.process.poll() is None
    log = exporter.log()
    assert f"cannot use the event database {str(database)!r}" in log
    assert "events are not being written" in log
