"""The transition watch on a real model and clock: what it records around an exporter's start."""

from __future__ import annotations

import time

from overseer.fleet.local import CHECK_INTERVAL_SECONDS, TransitionWatch
from overseer.messages import DiagnosticArray, DiagnosticStatus
from overseer.model import FleetLimits, FleetModel, RememberedRobot
from overseer.model.events import Event

ARRAY = DiagnosticArray(0, 0, "", (DiagnosticStatus(0, "/a", "fine", "hw", ()),))


def watched(limits: FleetLimits) -> tuple[FleetModel, TransitionWatch, list[Event]]:
    """A model and a watch collecting its events, not started."""
    model = FleetModel(limits)
    events: list[Event] = []
    return model, TransitionWatch(model, events.extend), events


def test_a_remembered_robot_heard_at_once_after_a_restart_continues_its_run_without_an_event() -> None:
    model, watch, events = watched(FleetLimits(robot_timeout=30.0))
    model.remember([RememberedRobot("r1", "dds", time.time() - 1.0)])  # heard a second before the restart
    watch.start()
    try:
        model.apply("r1", ARRAY, "dds", feed="writer")  # the transports deliver before the watch's next look
        time.sleep(2.5 * CHECK_INTERVAL_SECONDS)
    finally:
        watch.stop()
    # Its component appeared; no robot_up says the robot came up.
    assert [event.kind for event in events if event.robot == "r1"] == ["appeared"]


def test_a_robot_first_heard_after_the_start_comes_up_with_an_event() -> None:
    model, watch, events = watched(FleetLimits(robot_timeout=30.0))
    watch.start()
    try:
        model.apply("r2", ARRAY, "dds", feed="writer")
        deadline = time.monotonic() + 10 * CHECK_INTERVAL_SECONDS
        while not any(event.kind == "robot_up" for event in events) and time.monotonic() < deadline:
            time.sleep(0.05)
    finally:
        watch.stop()
    up = [event for event in events if event.kind == "robot_up"]
    assert [(event.robot, event.old_level, event.message) for event in up] == [
        ("r2", None, "first diagnostics received")
    ]
