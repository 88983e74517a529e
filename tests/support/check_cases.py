"""The outcomes the check, Nagios and Icinga 2 must all report alike, and their golden files.

The golden files in tests/golden/check/ hold the check's own output for each case; each server's view of
a result is rebuilt into the plugin format and compared with them.
"""

from __future__ import annotations

import os
import re
from dataclasses import dataclass

from support.paths import GOLDEN
from testbed.nagios import PluginResult

GOLDEN_DIR = GOLDEN / "check"
UPDATE_GOLDEN = os.environ.get("OVERSEER_UPDATE_GOLDEN") == "1"


@dataclass(frozen=True)
class CheckCase:
    """One outcome the check, Icinga 2 and Nagios must all report the same way."""

    golden: str
    robot: str
    name_filter: str
    state: int
    icinga2_service: str
    nagios_service: str


CASES = (
    CheckCase("robot_ok", "robot1", "", 0, "ros-diagnostics", "ROS diagnostics"),
    CheckCase("robot_warn_and_stale", "robot2", "", 1, "ros-diagnostics", "ROS diagnostics"),
    CheckCase("robot_error", "robot3", "", 2, "ros-diagnostics", "ROS diagnostics"),
    CheckCase("robot_down", "robot4", "", 3, "ros-diagnostics", "ROS diagnostics"),
    CheckCase("battery_filter", "robot3", "battery", 1, "ros-battery", "ROS batteries"),
)


def normalize(output: str) -> str:
    """Plugin output without what changes from run to run: ports and the seconds since a robot spoke."""
    output = re.sub(r"127\.0\.0\.1:\d+", "127.0.0.1:PORT", output)
    return re.sub(r"no diagnostics received for \d+ s", "no diagnostics received for N s", output)


def assert_matches_golden(golden: str, result: PluginResult) -> None:
    """The normalized output equals tests/golden/check/<golden>.txt, whose first line is the exit status.

    OVERSEER_UPDATE_GOLDEN=1 rewrites the file instead (review the diff before committing it).
    """
    actual = f"exit status {result.state}\n{normalize(result.output).rstrip(chr(10))}\n"
    path = GOLDEN_DIR / f"{golden}.txt"
    if UPDATE_GOLDEN:
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(actual, encoding="utf-8")
    assert path.exists(), f"missing golden file {path}; create it with OVERSEER_UPDATE_GOLDEN=1"
    assert actual == path.read_text(encoding="utf-8")
