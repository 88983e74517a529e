"""Moved feeds are forgotten a second after the move, by the robot they left, with its last feed telling."""

from __future__ import annotations

from overseer.messages import DiagnosticArray, DiagnosticStatus
from overseer.model import FleetModel
from overseer.sources.reattribution import MovedFeeds
from support.clock import ManualClock


def test_a_moved_feed_is_forgotten_a_second_later_and_its_robot_with_it_when_it_was_all() -> None:
    clock = ManualClock(100.0)
    model = FleetModel()
    for feed, name in (("writer", "drive: Motor"), ("other", "Disk")):
        array = DiagnosticArray(0, 0, "", (DiagnosticStatus(0, name, "ok", "", ()),))
        model.apply("domain0", array, "dds", feed=feed)
    moved = MovedFeeds(model, clock=clock)
    moved.moved("domain0", "writer")
    clock.now += 0.5
    moved.forget(lambda robot: True)  # a sample taken before the move may still be on its way
    assert [key[0] for key in model.snapshot().robots[0].components] == ["drive: Motor", "Disk"]
    clock.now += 0.5
    moved.forget(lambda robot: True)
    moved.forget(lambda robot: True)  # once
    assert [key[0] for key in model.snapshot().robots[0].components] == ["Disk"]
    moved.moved("domain0", "other")
    clock.now += 1.0
    moved.forget(lambda robot: False)
    assert model.snapshot().robots == () and model.snapshot().forgotten_counts == {"reattributed": 1}
