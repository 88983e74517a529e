"""`/metrics` tells how long it waited for the fleet's series before its first byte, scrape after scrape.

The unit tests time renders by a clock stepped by hand; the HTTP test serves a real endpoint whose fleet
takes a known time to render, and reads each scrape's figures back with prometheus-client's parser. The
real Prometheus reads them in `test_render_ahead.py`.
"""

from __future__ import annotations

import re
import time
import urllib.request
from collections.abc import Iterator
from contextlib import contextmanager

import pytest
from prometheus_client.parser import text_string_to_metric_families

from overseer.fleet.exposition import ExpositionPart, FleetExposition
from overseer.fleet.local import LocalFleet
from overseer.messages import DiagnosticArray, DiagnosticStatus
from overseer.model import FleetModel
from overseer.serve.assembler import ExpositionAssembler
from overseer.serve.http import OverseerServer
from overseer.serve.render_timing import RenderTiming, RenderTimingCollector
from testbed.model_server import serving_fleet

RENDER_SECONDS = 0.2


class _SteppedClock:
    """A clock that reads `step` seconds later at each call."""

    def __init__(self, step: float) -> None:
        """At 0, moving `step` seconds a reading."""
        self.now, self.step = 0.0, step

    def __call__(self) -> float:
        """The time, `step` later than the last reading."""
        self.now += self.step
        return self.now


def test_each_render_is_counted_with_its_seconds_and_the_last_kept() -> None:
    timing = RenderTiming(_SteppedClock(0.25))
    assert timing.timed(lambda: "first") == "first"
    assert timing.timed(lambda: "second") == "second"
    assert timing.read() == (2, 0.5, 0.25)


def test_a_render_that_raises_is_not_counted_and_its_error_goes_on() -> None:
    timing = RenderTiming(_SteppedClock(1.0))
    timing.timed(lambda: None)

    def failing() -> None:
        raise RuntimeError("a worker restarting")

    with pytest.raises(RuntimeError, match="a worker restarting"):
        timing.timed(failing)
    assert timing.read() == (1, 1.0, 1.0)


class _SlowFleet(LocalFleet):
    """A fleet whose series take `RENDER_SECONDS` to render, as a large one's do."""

    def exposition_parts(self) -> list[ExpositionPart]:
        time.sleep(RENDER_SECONDS)
        return super().exposition_parts()


@contextmanager
def _slow_server() -> Iterator[OverseerServer]:
    model = FleetModel()
    model.apply_array("r1", DiagnosticArray(0, 0, "", (DiagnosticStatus(0, "motor", "ok", "hw"),)), "dds")
    timing = RenderTiming()
    fleet = _SlowFleet(model, [], FleetExposition(model, re.compile(".*")))
    assembler = ExpositionAssembler(["dds"], [RenderTimingCollector(timing)])
    with serving_fleet(fleet, assembler, render_timing=timing) as server:
        yield server


def _scrape(server: OverseerServer) -> dict[str, float]:
    port = server.server_address[1]
    with urllib.request.urlopen(f"http://127.0.0.1:{port}/metrics", timeout=10) as answer:
        text = answer.read().decode()
    return {
        sample.name: sample.value
        for family in text_string_to_metric_families(text)
        if family.name.startswith("overseer_exposition_")
        for sample in family.samples
    }


def test_each_scrape_shows_how_long_it_waited_for_its_own_series() -> None:
    with _slow_server() as server:
        first = _scrape(server)
        second = _scrape(server)
    # The series are rendered before the exporter's own families are written: each scrape counts itself.
    assert first["overseer_exposition_render_duration_seconds_count"] == 1
    assert RENDER_SECONDS <= first["overseer_exposition_last_render_seconds"] < 5
    assert second["overseer_exposition_render_duration_seconds_count"] == 2
    assert RENDER_SECONDS <= second["overseer_exposition_last_render_seconds"] < 5
    assert second["overseer_exposition_render_duration_seconds_sum"] == pytest.approx(
        first["overseer_exposition_last_render_seconds"] + second["overseer_exposition_last_render_seconds"]
    )
