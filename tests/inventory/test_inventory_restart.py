"""Nothing forgotten silently: `overseer run` processes with simulated DDS robots, stopped and restarted.

A robot heard is remembered across a restart of the exporter (its database), down as it was, with the
time it was last heard, and without an event saying it came up; listed robots are there from the start;
SIGHUP reads the inventory again; a retired robot stays forgotten after a restart. With one ingest
process and with two.
"""

from __future__ import annotations

import os
import signal
import time
from pathlib import Path
from typing import Any

import pytest

from testbed.processes import Exporter, running_exporter, running_simulator, wait_for

pytestmark = pytest.mark.servers

WORKERS = [1, 2]


def robots(exporter: Exporter) -> dict[str, dict[str, Any]]:
    return {robot["robot"]: robot for robot in exporter.get_json("/api/v1/robots")["robots"]}


def events(exporter: Exporter, robot: str) -> list[tuple[str, str]]:
    """(kind, message) of the robot's events, oldest first."""
    answer = exporter.get_json(f"/api/v1/events?robot={robot}&limit=1000")
    return [(event["kind"], event["message"]) for event in reversed(answer["events"])]


def flags(tmp_path: Path, workers: int) -> list[str]:
    return [
        f"--ingest.workers={workers}",
        f"--events.path={tmp_path / 'overseer-events.db'}",
        "--fleet.stale-after=1s",
        "--fleet.robot-timeout=2s",
    ]


@pytest.mark.parametrize("workers", WORKERS)
def test_robots_heard_are_remembered_down_across_a_restart_and_come_back_as_they_would(
    tmp_path: Path, dds_domain: int, workers: int
) -> None:
    with running_exporter(tmp_path, dds_domain, *flags(tmp_path, workers)) as first:
        with running_simulator(tmp_path, dds_domain, "--robots", "2"):
            wait_for(lambda: all(r["up"] for r in robots(first).values()) and len(robots(first)) == 2, 30)
        wait_for(lambda: not any(r["up"] for r in robots(first).values()), 15, message="both down")
        wait_for(
            # Events are written a quarter second at a time: none may be written yet when both are down.
            lambda: all(
                (recorded := events(first, name)) and recorded[-1][0] == "robot_down"
                for name in ("robot1", "robot2")
            ),
            10,
            message="robot_down recorded",
        )
        before = robots(first)
        first_events = {name: events(first, name) for name in before}
    with running_exporter(tmp_path, dds_domain, *flags(tmp_path, workers)) as second:
        after = robots(second)
        assert set(after) == {"robot1", "robot2"}
        for name, robot in after.items():
            assert (robot["up"], robot["down_reason"]) == (False, before[name]["down_reason"])
            assert robot["last_message"] == pytest.approx(before[name]["last_message"], abs=0.001)
        samples = second.samples()
        assert samples["ros_diagnostics_robot_up"] == {(("robot", "robot1"),): 0, (("robot", "robot2"),): 0}
        assert set(samples["ros_diagnostics_robot_last_message_timestamp_seconds"]) == {
            (("robot", "robot1"),),
            (("robot", "robot2"),),
        }
        time.sleep(2.5)  # two checks of the event detector and more, for an event it must not record
        assert {name: events(second, name) for name in after} == first_events  # no event for the restart
        with running_simulator(tmp_path, dds_domain, "--robots", "2"):
            wait_for(lambda: all(r["up"] for r in robots(second).values()), 30, message="back up")
            returned = ("robot_up", "diagnostics received again")
            wait_for(
                lambda: returned in events(second, "robot1")[len(first_events["robot1"]) :],
                10,
                message="robot_up recorded",
            )


@pytest.mark.parametrize("workers", WORKERS)
def test_a_listed_robot_never_heard_is_down_from_the_start_and_sighup_reads_the_inventory_again(
    tmp_path: Path, dds_domain: int, workers: int
) -> None:
    inventory = tmp_path / "inventory.yml"
    inventory.write_text(
        "robots:\n  robot1: {labels: {site: a}, expected: [/Wheels/FL]}\n  ghost: {labels: {site: a}}\n",
        encoding="utf-8",
    )
    with (
        running_exporter(
            tmp_path, dds_domain, *flags(tmp_path, workers), f"--inventory.file={inventory}"
        ) as run,
        running_simulator(tmp_path, dds_domain, "--robots", "2"),
    ):
        known = robots(run)
        assert known["ghost"]["down_reason"] == "never_heard" and known["ghost"]["labels"] == {"site": "a"}
        wait_for(lambda: robots(run)["robot1"]["up"] and "robot2" in robots(run), 30, message="robots heard")
        robot1 = run.get_json("/api/v1/robots/robot1")
        assert {c["name"]: c["reported"] for c in robot1["components"]}["/Wheels/FL"] is False
        inventory.write_text("robots:\n  robot2: {labels: {site: b, team: night}}\n", encoding="utf-8")
        os.kill(run.process.pid, signal.SIGHUP)
        wait_for(
            lambda: robots(run)["robot2"]["labels"] == {"site": "b", "team": "night"}, 10, message="reload"
        )
        after = robots(run)
        assert "ghost" not in after  # no longer listed, never heard: forgotten
        assert after["robot1"]["listed"] is False and after["robot1"]["labels"] == {}
        assert "/Wheels/FL" not in {c["name"] for c in run.get_json("/api/v1/robots/robot1")["components"]}
        samples = run.samples()
        assert samples["overseer_robots_forgotten_total"][(("reason", "unlisted"),)] == 1
        assert (
            samples["ros_diagnostics_robot_info"][(("robot", "robot2"), ("site", "b"), ("team", "night"))]
            == 1
        )
        wait_for(lambda: events(run, "ghost") == [("unlisted", "removed from the inventory")], 10)
