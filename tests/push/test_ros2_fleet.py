"""The fleet as a DiagnosticArray back into ROS: one status per robot, worded from the API's summaries."""

from __future__ import annotations

from typing import Any

import pytest

from overseer.codec.cdr import decode_diagnostic_array, encode_diagnostic_array

pytest.importorskip("rclpy", reason="the ros2 extra (pip install overseer[ros2]) is not installed")

from overseer.push.ros2_fleet import fleet_array, robot_status


def summary(**overrides: Any) -> dict[str, Any]:
    robot: dict[str, Any] = {
        "robot": "site_a/robot7",
        "level": 2,
        "state": "ERROR",
        "up": True,
        "publisher_alive": True,
        "last_message": 1_000.0,
        "transport": "ros2",
        "components": 12,
        "counts": {"ok": 9, "warn": 1, "error": 2, "stale": 0},
    }
    return {**robot, **overrides}


@pytest.mark.parametrize(
    ("overrides", "level", "message"),
    [
        ({}, 2, "2 error, 1 warn"),
        ({"level": 0, "counts": {"ok": 12, "warn": 0, "error": 0, "stale": 0}}, 0, "all 12 OK"),
        ({"level": 3, "counts": {"ok": 10, "warn": 0, "error": 0, "stale": 2}}, 3, "2 stale"),
        ({"up": False, "level": 3}, 3, "down 12 s: no diagnostics"),
        ({"up": False, "publisher_alive": False}, 3, "down: its diagnostics publisher left"),
        ({"up": False, "last_message": None}, 3, "down: never heard from"),
    ],
)
def test_each_robot_is_a_status_at_its_worst_level_saying_why(
    overrides: dict[str, Any], level: int, message: str
) -> None:
    status = robot_status(summary(**overrides), now=1_012.4)
    assert (status.level, status.message) == (level, message)
    assert status.name == status.hardware_id == "site_a/robot7"
    values = dict(status.values)
    assert values["components"] == "12" and values["transport"] == "ros2"
    assert values["up"] == ("true" if overrides.get("up", True) else "false")


def test_the_fleet_array_is_stamped_and_decodes_as_ros_sends_it() -> None:
    document = {"generated_at": 1_700_000_000.25, "robots": [summary(), summary(robot="beta", level=0)]}
    array = fleet_array(document)
    decoded = decode_diagnostic_array(encode_diagnostic_array(array))
    assert (decoded.stamp_sec, decoded.stamp_nanosec) == (1_700_000_000, 250_000_000)
    assert [status.name for status in decoded.statuses] == ["site_a/robot7", "beta"]
