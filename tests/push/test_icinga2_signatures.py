"""The push's kept signatures are always what working each robot out again gives."""

from __future__ import annotations

from overseer.messages import DiagnosticArray, DiagnosticStatus
from overseer.model import FleetLimits, FleetModel
from overseer.push.icinga2_results import Signatures, robot_signature
from support.clock import ManualClock


def array(*levels: int) -> DiagnosticArray:
    """An aggregator's array, one component a level."""
    statuses = tuple(
        DiagnosticStatus(level, f"/Power/part{i}", "m", "hw", ()) for i, level in enumerate(levels)
    )
    return DiagnosticArray(0, 0, "", statuses)


def test_kept_signatures_follow_levels_staleness_down_and_a_robot_followed_again() -> None:
    clock = ManualClock(100.0)
    model = FleetModel(FleetLimits(stale_after=5, robot_timeout=10, stale_periods=1), clock=clock)
    signatures = Signatures()
    seen = []

    def look() -> None:
        # Twice: now, and a little later with nothing heard (the versions looked at last, kept).
        for _ in range(2):
            snapshot = model.snapshot()
            for robot in snapshot.robots:
                kept = signatures.of(snapshot, robot)
                assert kept == robot_signature(snapshot, robot), (robot.name, clock.now)
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
    signatures.forget("b")
    model.apply("b", array(1), "dds")  # followed again, its revisions start over
    look()
    assert len(set(seen)) >= 5
