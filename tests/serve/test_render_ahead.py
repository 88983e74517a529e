"""The series are rendered shortly before the scrape a steady scraper is expected to make.

Unit tests drive the cadence through given times and the thread through real ones (short intervals);
the last test has Debian's Prometheus scrape an exporter with two ingest workers and a simulated fleet,
and reads from Prometheus that the exporter rendered ahead of its scrapes.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from pathlib import Path

import pytest

from overseer.serve.render_ahead import (
    FUTILE,
    MARGIN,
    MAX_SCRAPERS,
    MIN_PASS,
    SKIPPED_AFTER_FUTILE,
    RenderAhead,
    RenderAheadCollector,
    ScrapeCadence,
)
from support.clock import ManualClock
from testbed.ports import fresh_domain_id
from testbed.processes import running_exporter, running_simulator, wait_for
from testbed.prometheus import running_prometheus

PROMETHEUS = "127.0.0.1 Prometheus/2.42.0"


def cadence_of(scraper: str, *times: float, min_interval: float = 5.0) -> ScrapeCadence:
    cadence = ScrapeCadence(min_interval)
    for moment in times:
        cadence.scraped(scraper, moment)
    return cadence


def test_a_scraper_at_a_steady_interval_is_expected_one_interval_after_its_last_scrape() -> None:
    cadence = cadence_of(PROMETHEUS, 100.0, 160.0, 220.02)
    assert cadence.next_scrape(221.0, float("-inf")) == pytest.approx((280.04, 60.02))
    # Already rendered ahead for that scrape: nothing more is expected until it comes.
    assert cadence.next_scrape(275.0, 280.04) is None


def test_one_gap_or_unsteady_gaps_make_no_interval() -> None:
    assert cadence_of(PROMETHEUS, 100.0, 160.0).next_scrape(161.0, float("-inf")) is None
    assert cadence_of(PROMETHEUS, 100.0, 160.0, 190.0).next_scrape(191.0, float("-inf")) is None
    # A person's curl now and then does not count either.
    assert cadence_of("127.0.0.1 curl/7.88", 0.0, 40.0, 140.0).next_scrape(141.0, float("-inf")) is None


def test_intervals_below_the_minimum_are_not_rendered_ahead() -> None:
    assert cadence_of(PROMETHEUS, 0.0, 1.0, 2.0).next_scrape(2.5, float("-inf")) is None
    # At the minimum itself, a scrape a little early still counts.
    assert cadence_of(PROMETHEUS, 0.0, 5.0, 9.9995).next_scrape(10.0, float("-inf")) == pytest.approx(
        (14.999, 4.9995)
    )
    assert cadence_of(PROMETHEUS, 0.0, 1.0, 2.0, min_interval=1.0).next_scrape(2.5, float("-inf")) == (
        3.0,
        1.0,
    )


def test_a_scraper_that_stopped_is_not_expected_again() -> None:
    cadence = cadence_of(PROMETHEUS, 0.0, 10.0, 20.0)
    assert cadence.next_scrape(24.0, float("-inf")) == (30.0, 10.0)
    assert cadence.next_scrape(34.0, float("-inf")) == (30.0, 10.0)  # late: rendered at once
    assert cadence.next_scrape(36.0, float("-inf")) is None  # half an interval late: stopped


def test_the_earliest_of_several_scrapers_comes_first() -> None:
    cadence = cadence_of("10.0.0.1 Prometheus/2.42.0", 0.0, 60.0, 120.0)
    for moment in (-25.0, 35.0, 95.0):  # a second Prometheus (a pair), at another offset
        cadence.scraped("10.0.0.2 Prometheus/2.42.0", moment)
    assert cadence.next_scrape(121.0, float("-inf")) == (155.0, 60.0)
    assert cadence.next_scrape(121.0, 155.0) == (180.0, 60.0)


def test_the_scrapers_followed_are_bounded_and_the_least_recent_forgotten() -> None:
    cadence = cadence_of(PROMETHEUS, 0.0, 10.0, 20.0)
    for client in range(MAX_SCRAPERS):
        cadence.scraped(f"10.0.0.{client} curl", 21.0)
    assert cadence.next_scrape(22.0, float("-inf")) is None
    assert len(cadence._scrapers) == MAX_SCRAPERS


def test_the_thread_renders_once_shortly_before_each_expected_scrape() -> None:
    rendered: list[float] = []
    render_ahead = RenderAhead(lambda: rendered.append(time.monotonic()), min_interval=1.0)
    render_ahead.start()
    try:
        started = time.monotonic()
        for scrape in range(3):  # every 1.5 s: learned at the third
            time.sleep(max(0.0, started + 1.5 * scrape - time.monotonic()))
            render_ahead.scraped(PROMETHEUS)
        time.sleep(max(0.0, started + 4.5 - time.monotonic()))
        before_the_fourth = list(rendered)
        render_ahead.scraped(PROMETHEUS)
    finally:
        render_ahead.stop()
    # Half a second (the margin) before the scrape expected at 4.5 s, and only once.
    assert len(before_the_fourth) == 1
    assert 3.0 + 0.5 <= before_the_fourth[0] - started <= 4.5
    assert render_ahead.renders == 1 and render_ahead.failures == 0


def slow_renders(
    seconds: float, passes: float | None = None, min_interval: float = 1.0
) -> tuple[list[tuple[float, float]], RenderAhead]:
    """A render ahead whose first render takes `seconds` and the others `passes`; the (start, end) of each.

    The passes take two thirds of the first by default: they stay below FUTILE.
    """
    renders: list[tuple[float, float]] = []
    pass_seconds = 2 * seconds / 3 if passes is None else passes

    def render() -> None:
        started = time.monotonic()
        time.sleep(pass_seconds if renders else seconds)
        renders.append((started, time.monotonic()))

    return renders, RenderAhead(render, min_interval=min_interval)


def scrape_three_times(render_ahead: RenderAhead, started: float) -> float:
    """Scrapes at 0, 1.5 and 3 s from `started`: when the fourth is expected (about 4.5 s)."""
    times = []
    for scrape in range(3):
        time.sleep(max(0.0, started + 1.5 * scrape - time.monotonic()))
        times.append(time.monotonic())
        render_ahead.scraped(PROMETHEUS)
    return 2 * times[2] - times[1]


def test_a_long_render_is_followed_by_passes_until_the_scrape_begins() -> None:
    renders, render_ahead = slow_renders(0.12)
    render_ahead.start()
    try:
        started = time.monotonic()
        expected = scrape_three_times(render_ahead, started)
        time.sleep(max(0.0, expected - time.monotonic()))
        render_ahead.scraped(PROMETHEUS)
        scraped = time.monotonic()
        # Long enough for a pass more, before the render ahead of the next scrape (about 5.25 s).
        time.sleep(max(0.0, started + 4.9 - time.monotonic()))
    finally:
        render_ahead.stop()
    # The first begins half a second before 4.5 s; then pass after pass, each of what changed during the
    # one before, the last ending within half a pass of the scrape: it renders the last moments' changes.
    assert render_ahead.renders == 1 and render_ahead.failures == 0 and render_ahead.skipped == 0
    assert render_ahead.passes == len(renders) - 1 >= 2
    assert renders[0][0] - started >= 4.5 - MARGIN - 0.05
    assert scraped - 0.04 - 0.05 <= renders[-1][1] <= scraped + 0.04 + 0.05
    assert render_ahead.last_seconds == pytest.approx(0.12, abs=0.05)  # the first pass's


def passes_toward(due: float, seconds: float, ahead: float | None = None) -> tuple[list[float], bool | None]:
    """When each pass after a render ahead began (every one `seconds` on a hand clock), and whether futile.

    The render ahead took `ahead` (by default twice a pass) and ended at 0; the scrape is `due` and does
    not begin meanwhile.
    """
    clock = ManualClock(0.0)
    began: list[float] = []

    def render() -> None:
        began.append(clock.now)
        clock.now += seconds

    render_ahead = RenderAhead(render, clock=clock)
    futile = render_ahead._render_until_scraped(2 * seconds if ahead is None else ahead, 0, due)
    return began, futile


def test_a_pass_that_would_end_within_half_its_length_after_the_scrape_is_begun() -> None:
    # The second pass, from 0.29 s, ends at 0.58 s: 0.08 s after the scrape, within 0.145 s.
    assert passes_toward(0.5, 0.29) == ([0.0, 0.29], False)
    # Passes of 0.2 s toward a scrape at 1 s: the last, from 0.8 s, ends at it; one from 1 s would not.
    began, futile = passes_toward(1.0, 0.2)
    assert began == pytest.approx([0.0, 0.2, 0.4, 0.6, 0.8]) and not futile


def test_a_pass_that_would_keep_the_scrape_waiting_longer_is_not_begun() -> None:
    # A third pass, from 0.48 s, would end at 0.72 s, 0.22 s after the scrape: the scrape renders what
    # it would have, without waiting for it.
    assert passes_toward(0.5, 0.24) == ([0.0, 0.24], False)
    assert passes_toward(0.1, 0.3) == ([], None)  # the scrape is nearer than half a pass: nothing measured


def test_a_pass_nearly_as_long_as_its_render_ahead_ends_the_passes() -> None:
    # Nearly all the render ahead rendered changed again during the pass: so it will before the scrape.
    assert passes_toward(1.0, FUTILE * 0.2, ahead=0.2) == ([0.0], True)
    assert passes_toward(1.0, 0.25, ahead=0.2) == ([0.0], True)
    # A pass a little shorter stays below FUTILE: the passes go on toward the scrape.
    began, futile = passes_toward(1.0, 0.8 * 0.2, ahead=0.2)
    assert len(began) == 6 and not futile


class HandClockRenderAhead(RenderAhead):
    """The render-ahead loop run in the test's thread on a hand clock, through a list of scrape times.

    Sleeping moves the clock on to the next scrape (which it then makes) or to the time asked; every
    render ahead takes `ahead` seconds and every pass `passes` (or `passes(renders ahead so far)`); the
    loop stops after `until`.
    """

    def __init__(
        self, scrapes: list[float], ahead: float, passes: float | Callable[[int], float], until: float
    ) -> None:
        """Scrapes at `scrapes` (seconds, in order), renders of `ahead` then `passes` seconds."""
        self.clock = ManualClock(0.0)
        self.began: list[float] = []  # when each render began
        self._pending = list(scrapes)
        self._ahead = ahead
        self._passes = passes if callable(passes) else lambda _: passes
        self._until = until
        self._last_end = float("-inf")
        super().__init__(self._render_for_a_while, min_interval=0.5, clock=self.clock)

    def _render_for_a_while(self) -> None:
        # A render that begins as the one before ended is a pass.
        clock = self.clock
        self.began.append(clock.now)
        clock.now += self._passes(self.renders) if clock.now == self._last_end else self._ahead
        self._last_end = clock.now

    def _sleep(self, seconds: float | None) -> None:
        clock = self.clock
        wake = clock.now + seconds if seconds is not None else float("inf")
        if self._pending and self._pending[0] <= wake:
            clock.now = max(clock.now, self._pending.pop(0))
            self.scraped(PROMETHEUS)
        else:
            clock.now = wake
        if clock.now > self._until:
            self._stopping.set()


def test_after_two_futile_render_aheads_the_scrapes_of_three_intervals_are_not_rendered_ahead_of() -> None:
    # Every pass longer than its render ahead: it rendered again all that the render ahead did.
    scrapes = [1.5 * scrape for scrape in range(12)]
    render_ahead = HandClockRenderAhead(scrapes, ahead=0.1, passes=0.15, until=16.6)
    render_ahead._run()
    # Learned at the third scrape (3 s); rendered ahead of the fourth and fifth (4.5 and 6 s), half a
    # second and 0.7 s (twice the last render and the margin) before, a futile pass after each; the
    # scrapes of the next three intervals (7.5, 9 and 10.5 s) skipped; rendered ahead of the ninth (12 s),
    # futile again: the next three skipped again (13.5, 15 and 16.5 s).
    assert render_ahead.began == pytest.approx([4.0, 4.1, 5.3, 5.4, 11.3, 11.4])
    assert render_ahead.skipped == 2 * SKIPPED_AFTER_FUTILE
    assert render_ahead.renders == 3 and render_ahead.passes == 3 and render_ahead.failures == 0
    family = next(iter(RenderAheadCollector(render_ahead).collect()))
    counts = {sample.labels["result"]: sample.value for sample in family.samples}
    assert counts == {"done": 3.0, "failed": 0.0, "skipped": float(2 * SKIPPED_AFTER_FUTILE)}


def test_one_futile_render_ahead_or_passes_that_stay_shorter_skip_nothing() -> None:
    scrapes = [1.5 * scrape for scrape in range(12)]
    # Passes of 0.08 s after renders ahead of 0.1 s: below FUTILE, every scrape is rendered ahead of.
    converging = HandClockRenderAhead(scrapes, ahead=0.1, passes=0.08, until=16.6)
    converging._run()
    assert converging.renders == 9 and converging.skipped == 0 and converging.passes >= 9
    # Every other render ahead's pass futile (a busy machine), the others' shorter: nothing skipped.
    sometimes = HandClockRenderAhead(
        scrapes, ahead=0.1, passes=lambda renders: (0.06, 0.15)[renders % 2], until=16.6
    )
    sometimes._run()
    assert sometimes.renders == 9 and sometimes.skipped == 0
    assert sometimes.began[:6] == pytest.approx([4.0, 4.1, 5.3, 5.4, 5.46, 5.52])


def test_passes_stop_about_when_a_scrape_that_does_not_come_was_due() -> None:
    renders, render_ahead = slow_renders(0.12)
    render_ahead.start()
    try:
        started = time.monotonic()
        expected = scrape_three_times(render_ahead, started)
        time.sleep(max(0.0, started + 6.0 - time.monotonic()))  # the scraper stopped after its third
    finally:
        render_ahead.stop()
    assert render_ahead.passes >= 2
    # The last pass ended within half a pass of the scrape expected, and none began after it.
    assert expected - 0.04 - 0.05 <= renders[-1][1] <= expected + 0.04 + 0.05
    assert len(renders) == render_ahead.passes + 1


def test_a_render_quicker_than_a_pass_is_worth_has_no_pass_after_it() -> None:
    renders, render_ahead = slow_renders(MIN_PASS / 50)
    render_ahead.start()
    try:
        started = time.monotonic()
        scrape_three_times(render_ahead, started)
        time.sleep(max(0.0, started + 5.2 - time.monotonic()))
    finally:
        render_ahead.stop()
    assert render_ahead.renders == 1 and render_ahead.passes == 0 and len(renders) == 1


def test_a_render_that_fails_is_counted_and_the_thread_goes_on() -> None:
    calls: list[float] = []
    done = threading.Event()

    def failing() -> None:
        calls.append(time.monotonic())
        if len(calls) == 2:
            done.set()
        raise RuntimeError("a worker is restarting")

    render_ahead = RenderAhead(failing, min_interval=0.5)
    render_ahead.start()
    try:
        started = time.monotonic()
        for scrape in range(5):  # every second: learned at the third, renders before the fourth and fifth
            time.sleep(max(0.0, started + scrape - time.monotonic()))
            render_ahead.scraped(PROMETHEUS)
        assert done.wait(3.0)
    finally:
        render_ahead.stop()
    assert render_ahead.failures >= 2 and render_ahead.renders == 0


@pytest.mark.servers
def test_prometheus_scrapes_are_learned_and_the_workers_render_ahead_of_them(tmp_path: Path) -> None:
    domain = fresh_domain_id()
    with (
        running_simulator(tmp_path, domain, "--robots=4", "--rate=2"),
        running_exporter(tmp_path, domain, "--ingest.workers=2") as exporter,
    ):
        target = exporter.url.removeprefix("http://")
        config = {
            "global": {"scrape_interval": "5s", "scrape_timeout": "4s"},
            "scrape_configs": [{"job_name": "overseer", "static_configs": [{"targets": [target]}]}],
        }
        with running_prometheus(tmp_path, config) as prometheus:

            def renders_ahead() -> dict[str, float]:
                found = prometheus.query("overseer_exposition_renders_ahead_total")
                return {sample["metric"]["result"]: float(sample["value"][1]) for sample in found}

            # Learned at the third scrape (10 s), rendered before the fourth, seen by the fifth.
            counts = wait_for(lambda: (c := renders_ahead()).get("done", 0) >= 2 and c, 60, 1.0)
            assert counts["failed"] == 0 and counts["skipped"] == 0
            seconds = prometheus.query("overseer_exposition_render_ahead_seconds")
            assert 0 < float(seconds[0]["value"][1]) < 4
            # Each scrape's own wait for the series, as Prometheus stored it beside its scrape duration.
            rendered = prometheus.query("overseer_exposition_render_duration_seconds_count")
            assert float(rendered[0]["value"][1]) >= 4
            last = prometheus.query("overseer_exposition_last_render_seconds")
            assert 0 < float(last[0]["value"][1]) < 4
            # Stored at the scrape it timed, and a part of it (one query: no scrape comes between).
            within = prometheus.query("overseer_exposition_last_render_seconds <= scrape_duration_seconds")
            assert len(within) == 1
            robots = prometheus.query("count(ros_diagnostics_robot_up == 1)")
            assert robots and float(robots[0]["value"][1]) == 4
