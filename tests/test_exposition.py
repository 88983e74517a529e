"""The fast text exposition renders exactly what prometheus-client renders from the collector."""

from __future__ import annotations

import re

import pytest
from prometheus_client import generate_latest
from prometheus_client.registry import CollectorRegistry

from overseer.exposition import FleetExposition
from overseer.messages import DiagnosticArray, DiagnosticStatus
from overseer.metrics import FleetCollector
from overseer.model import FleetLimits, FleetModel


class Clock:
    """A hand-moved clock."""

    def __init__(self) -> None:
        """Start at a fixed unix time."""
        self.now = 1_700_000_000.0

    def __call__(self) -> float:
        """The current time."""
        return self.now


HOSTILE = ['quote"d', "back\\slash", "new\nline", "unicode ☃ 🤖", "brace}{=,", "tab\there", "", "\ufffd"]


def fleet() -> tuple[FleetModel, Clock]:
    clock = Clock()
    model = FleetModel(FleetLimits(stale_after=5, robot_timeout=10, expire_after=60), clock=clock)
    for index, name in enumerate(HOSTILE):
        statuses = (
            DiagnosticStatus(
                index % 4, name or "/empty", name, name, ((name, "1.5"), ("v", "12 V"), ("v", "3"))
            ),
            DiagnosticStatus(
                1,
                "/Motor",
                "warm",
                "m1",
                (("nan", "nan"), ("inf", "-inf"), ("big", "1e300"), ("z", "0"), ("nz", "-0")),
            ),
        )
        model.apply(f"robot{index}/{name}", DiagnosticArray(0, 0, "", statuses), "dds")
    model.count_message("ros1", "decode_error")
    model.count_source_error("ros1", "master_unreachable")
    model.count_source_error("ros1", 'odd "reason"')
    return model, clock


def both(model: FleetModel, exposition: FleetExposition, value_keys: str = ".*") -> tuple[bytes, bytes]:
    registry = CollectorRegistry()
    registry.register(FleetCollector(model, re.compile(value_keys), ["dds"]))
    return exposition.render(), generate_latest(registry)


@pytest.mark.parametrize("value_keys", [".*", "v|big"])
def test_fast_exposition_equals_collector_through_changes_staleness_and_expiry(value_keys: str) -> None:
    model, clock = fleet()
    exposition = FleetExposition(model, re.compile(value_keys), ["dds"])
    fast, reference = both(model, exposition, value_keys)
    assert fast == reference
    steps = [
        lambda: model.apply(
            "robot1/back\\slash", DiagnosticArray(0, 0, "", (DiagnosticStatus(2, "/new", "", "", ()),)), "dds"
        ),
        lambda: model.touch("robot2/new\nline", "dds"),
        lambda: setattr(clock, "now", clock.now + 6),  # most components stale
        lambda: model.touch("robot3/unicode ☃ 🤖", "dds"),
        lambda: setattr(clock, "now", clock.now + 5),  # robots down
        lambda: model.touch("robot3/unicode ☃ 🤖", "dds"),
        lambda: setattr(clock, "now", clock.now + 60),
        model.expire,
    ]
    for step in steps:
        step()
        fast, reference = both(model, exposition, value_keys)
        assert fast == reference


def test_cached_lines_are_reused_for_unchanged_robots() -> None:
    model, _ = fleet()
    exposition = FleetExposition(model, re.compile(".*"), ["dds"])
    exposition.render()
    cached = dict(exposition._robots)
    model.touch('robot0/quote"d', "dds")
    exposition.render()
    assert all(exposition._robots[name] is lines for name, lines in cached.items())
