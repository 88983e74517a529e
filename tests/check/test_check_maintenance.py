"""A robot in maintenance: the check says so in its output and keeps its state; the API's field read strictly.

Pure functions: no exporter, no network.
"""

from __future__ import annotations

from typing import Any

import pytest

from overseer.check.document import CheckError, robot_from_document
from overseer.verdict import (
    CRITICAL,
    UNKNOWN,
    Maintenance,
    ReportedComponent,
    ReportedRobot,
    Settings,
    judge,
    plugin_output,
)

UNTIL = 1795521600.0  # 2026-11-24 12:00 UTC


def document(**changes: Any) -> dict[str, Any]:
    base: dict[str, Any] = {
        "robot": "site_a/r7",
        "up": True,
        "last_message": 100.0,
        "generated_at": 101.0,
        "components": [
            {"name": "/Laser", "hardware_id": "", "level": 2, "message": "no scans", "values": []}
        ],
        "maintenance": {"window": "w3", "until": UNTIL, "author": "alice", "comment": "laser swap"},
    }
    return {**base, **changes}


def test_the_window_is_added_to_the_status_line_and_the_state_is_unchanged() -> None:
    robot = robot_from_document(document())
    without = robot_from_document(document(maintenance=None))
    verdict, plain = judge(robot, Settings()), judge(without, Settings())
    assert verdict.state == plain.state == CRITICAL
    assert (
        verdict.status_text
        == plain.status_text + " [in maintenance until 2026-11-24 12:00 UTC, alice: laser swap]"
    )
    assert verdict.perfdata == plain.perfdata


def test_a_robot_down_in_maintenance_is_still_down_and_says_why_it_is_quiet() -> None:
    robot = ReportedRobot("r1", False, 50.0, 100.0, [], maintenance=Maintenance("w1", UNTIL, "bob", "parked"))
    verdict = judge(robot, Settings())
    assert verdict.state == UNKNOWN
    assert verdict.status_text.startswith(
        "UNKNOWN - r1 is down: no diagnostics received for 50 s [in maintenance"
    )


def test_hostile_comments_stay_on_the_status_line_without_starting_perfdata() -> None:
    comment = "a|b='1'\nCRITICAL - forged line\t" + "x" * 200
    robot = ReportedRobot(
        "r1",
        True,
        100.0,
        101.0,
        [ReportedComponent("/A", "", 0, "ok", [])],
        maintenance=Maintenance("w1", UNTIL, "eve|x", comment),
    )
    output = plugin_output(judge(robot, Settings()))
    status_line = output.splitlines()[0]
    assert output.count("|") == 1 and " | " in status_line, "only the perfdata separator"
    assert "\n" not in status_line and "CRITICAL - forged line" in status_line
    assert status_line.split(" | ")[0].endswith("...]")


def test_older_exporters_without_the_field_are_read_as_no_window() -> None:
    old = document()
    del old["maintenance"]
    assert robot_from_document(old).maintenance is None


@pytest.mark.parametrize(
    ("maintenance", "error"),
    [
        ("w1", "'maintenance' is not a JSON object or null"),
        (
            {"window": "w1", "until": "soon", "author": "a", "comment": "c"},
            "'until' is missing or not a JSON number",
        ),
        (
            {"window": "w1", "until": 1e400, "author": "a", "comment": "c"},
            "'until' of 'maintenance' is not a time",
        ),
        (
            {"window": "w1", "until": -5, "author": "a", "comment": "c"},
            "'until' of 'maintenance' is not a time",
        ),
        (
            {"window": "w1", "until": UNTIL, "author": None, "comment": "c"},
            "'author' is missing or not a JSON string",
        ),
        (
            {"window": 3, "until": UNTIL, "author": "a", "comment": "c"},
            "'window' is missing or not a JSON string",
        ),
    ],
)
def test_a_malformed_field_is_named(maintenance: object, error: str) -> None:
    with pytest.raises(CheckError, match=error):
        robot_from_document(document(maintenance=maintenance))
