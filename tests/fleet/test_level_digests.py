"""Kept digests are always what working each robot's signature out again gives, and move with it alone."""

from __future__ import annotations

import sys
import time

from overseer.fleet.level_digests import Signatures, robot_signature
from overseer.messages import DiagnosticArray, DiagnosticStatus
from overseer.model import FleetLimits, FleetModel, RememberedRobot
from support.clock import ManualClock


def array(*levels: int, message: str = "m") -> DiagnosticArray:
    """An aggregator's array, one component a level."""
    statuses = tuple(
        DiagnosticStatus(level, f"/Power/part{i}", message, "hw", ()) for i, level in enumerate(levels)
    )
    return DiagnosticArray(0, 0, "", statuses)


def test_kept_digests_follow_levels_staleness_down_and_a_robot_followed_again() -> None:
    clock = ManualClock(100.0)
    model = FleetModel(FleetLimits(stale_after=5, robot_timeout=10, stale_periods=1), clock=clock)
    signatures = Signatures()
    seen = []

    def look() -> None:
        # Twice: now, and a little later with nothing heard (the versions looked at last, kept).
        for _ in range(2):
            snapshot = model.snapshot()
            digests = signatures.digests(snapshot)
            for robot in snapshot.robots:
                kept = digests[robot.name]
                assert kept == hash(robot_signature(snapshot, robot)), (robot.name, clock.now)
                seen.append(kept)
            clock.now += 0.5

    model.apply("a", array(0, 0), "dds")
    model.apply("b", array(0, 0), "dds")
    look()
    clock.now += 1
    model.apply("a", array(0, 0), "dds")  # the same again
    look()
    model.apply("a", array(0, 2), "dds")  # a level changed
    look()
    clock.now += 3.5  # b's components STALE a moment after this look, not heard since
    look()
    model.apply("a", array(0, 2), "dds")
    look()
    clock.now += 30  # b down
    model.apply("a", array(0, 2), "dds")
    look()
    assert model.retire("b") == "retired"
    look()  # b forgotten
    model.apply("b", array(1), "dds")  # followed again, its revisions start over
    look()
    assert len(set(seen)) >= 5


def test_digests_move_with_a_level_or_a_robot_down_and_not_with_a_message() -> None:
    clock = ManualClock(100.0)
    model = FleetModel(FleetLimits(stale_after=5, robot_timeout=10, stale_periods=1), clock=clock)
    signatures = Signatures()
    model.apply("a", array(0, 0), "dds")
    model.apply("b", array(0, 0), "dds")
    first = signatures.digests(model.snapshot())
    assert set(first) == {"a", "b"} and None not in first.values()
    model.apply("a", array(0, 0, message="other words, same levels"), "dds")
    assert signatures.digests(model.snapshot()) == first
    model.apply("a", array(0, 1), "dds")
    changed = signatures.digests(model.snapshot())
    assert changed["a"] != first["a"] and changed["b"] == first["b"]
    clock.now += 30  # both down
    model.apply("a", array(0, 1), "dds")
    down = signatures.digests(model.snapshot())
    assert down["a"] == changed["a"] and down["b"] != changed["b"]
    assert model.retire("b") == "retired"
    assert set(signatures.digests(model.snapshot())) == {"a"}  # and b's kept signature is dropped


def test_a_robot_remembered_from_before_the_start_has_no_digest_until_it_speaks() -> None:
    clock = ManualClock(100.0)
    model = FleetModel(FleetLimits(stale_after=5, robot_timeout=10), clock=clock)
    model.remember([RememberedRobot("r", "dds", time.time() - 1)])
    signatures = Signatures()
    assert signatures.digests(model.snapshot()) == {"r": None}
    model.apply("r", array(0), "dds")
    assert isinstance(signatures.digests(model.snapshot())["r"], int)


def test_a_robot_replaced_since_the_last_look_is_not_kept_alive_by_its_digest() -> None:
    clock = ManualClock(100.0)
    model = FleetModel(FleetLimits(), clock=clock)
    signatures = Signatures()
    model.apply("a", array(0, 0), "dds")
    signatures.digests(model.snapshot())
    looked_at = model.snapshot().robots[0]
    clock.now += 1
    model.apply("a", array(0, 2), "dds")  # a new version: the model no longer holds the one looked at
    # Kept for the next look, each robot's last version held every record it replaced (at 10,000 robots
    # over two workers, about 40 MB).
    assert sys.getrefcount(looked_at) == 2  # this test's name for it and getrefcount's argument
    assert signatures.digests(model.snapshot())["a"] == hash(
        robot_signature(model.snapshot(), model.snapshot().robots[0])
    )


def test_a_feed_touched_at_the_instant_of_another_feeds_message_moves_the_digest() -> None:
    clock = ManualClock(100.0)
    model = FleetModel(FleetLimits(stale_after=5, robot_timeout=60, stale_periods=1), clock=clock)
    signatures = Signatures()
    left, right = (
        DiagnosticArray(0, 0, "", (DiagnosticStatus(0, f"/{side}/part", "m", "hw", ()),))
        for side in ("Left", "Right")
    )
    for clock.now in (100.0, 110.0, 120.0):  # both feeds every 10 s: their components fresh for 10 s
        model.apply("a", left, "dds", topic="left", feed="left")
        model.apply("a", right, "dds", topic="right", feed="right")
    clock.now = 135.0
    model.apply("a", left, "dds", topic="left", feed="left")
    looked = signatures.digests(model.snapshot())["a"]  # the right feed's component STALE
    revision = model.snapshot().robots[0].revision
    # The right feed republishes the same array at the same clock reading: its own time alone moves.
    assert model.touch("a", "dds", "right")
    snapshot = model.snapshot()
    assert snapshot.robots[0].revision == revision and snapshot.robots[0].last_message == 135.0
    assert signatures.digests(snapshot)["a"] == hash(robot_signature(snapshot, snapshot.robots[0])) != looked
