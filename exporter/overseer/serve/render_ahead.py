"""Rendering the fleet's series shortly before Prometheus's next scrape, so that the scrape waits for less.

A scrape renders again every robot that changed since the one before. In a large fleet scraped a minute
apart nearly every robot did (10,000 robots, 1 % of statuses changing a second), and that rendering, seconds
of it, comes before the first byte: Prometheus counts it in `scrape_duration_seconds`. A scraper asks at a
fixed interval and offset, so when it will ask next is known from when it asked before. Shortly before
then, the fleet renders what changed (`Fleet.prepare_exposition`), and the scrape itself renders only what
changed in the last moments. Nothing is served from the render ahead: a change still reaches the very
next scrape.

At 10,000 robots the render ahead itself takes seconds, and most robots change again while it runs: a
scrape right after it would render most of them again. So while a render took long enough to matter, the
fleet renders again, each time only what changed during the render before, until the scrape begins: each
pass is shorter than the one before, and the scrape waits for the last moments' changes alone. A scrape
that begins during a pass waits for it, and then renders what changed meanwhile; so a pass that would
end later than half its length after the scrape is due is not begun (the scrape renders what it would
have, and waits less): the passes stop at the scrape, or about when it was due.

When statuses change faster than a render takes (every robot several times a second, or live values), a
pass renders nearly all the render ahead did: whatever it renders changes again before the scrape, which
renders it all once more. Such a pass (`FUTILE`) ends the passes. After two render aheads in a row whose
pass was futile (one could be a pass slowed by a busy machine), the scrapes of the next few intervals are
not rendered ahead of (`SKIPPED_AFTER_FUTILE`): those renders would only take the cores the ingest and
the scraper need. Then a render ahead tries again, in case the fleet calmed down; futile once more, the
scrapes after it are skipped again.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass

from prometheus_client.metrics_core import CounterMetricFamily, GaugeMetricFamily, Metric
from prometheus_client.registry import Collector

log = logging.getLogger(__name__)

MIN_INTERVAL = 5.0  # seconds between scrapes below which a scrape renders little: no render ahead
STEADY = 0.1  # two gaps between scrapes this close (a share of the gap) make a scraper's interval
LEAD = 2.0  # how many times as long as the last render ahead took the next begins before its scrape
MARGIN = 0.5  # seconds the render ahead begins before the scrape, beyond LEAD times the last one's
MIN_PASS = 0.05  # seconds: a render quicker leaves the scrape no more than that, so no pass after it
MAX_SCRAPERS = 16  # scrapers followed at once (a client that scrapes once is forgotten first)
FUTILE = 0.9  # a pass this long against its render ahead rendered nearly all it did again: no gain
FUTILE_IN_A_ROW = 2  # render aheads in a row with a futile pass before scrapes are skipped
SKIPPED_AFTER_FUTILE = 3  # intervals whose scrapes are then not rendered ahead of, before trying again


@dataclass
class _Scraper:
    """When one scraper last asked, the gap before that, and its interval once two gaps agree."""

    last: float
    gap: float | None = None
    interval: float | None = None


class ScrapeCadence:
    """The clients that scrape `/metrics` at a steady interval, and when each is expected next."""

    def __init__(self, min_interval: float = MIN_INTERVAL) -> None:
        """Know of no scraper yet; follow those that scrape at least `min_interval` seconds apart."""
        self._min_interval = min_interval
        self._scrapers: dict[str, _Scraper] = {}

    def scraped(self, scraper: str, now: float) -> None:
        """`scraper` (its address and user agent) began a scrape at `now` (monotonic seconds)."""
        known = self._scrapers.pop(scraper, None)  # popped and put back: the dict stays in order of use
        if known is None:
            if len(self._scrapers) >= MAX_SCRAPERS:
                del self._scrapers[next(iter(self._scrapers))]
            self._scrapers[scraper] = _Scraper(now)
            return
        gap = now - known.last
        steady = known.gap is not None and abs(gap - known.gap) <= STEADY * known.gap
        # A scraper at the minimum itself asks a fraction of a millisecond early as often as late.
        long_enough = gap >= self._min_interval * (1 - STEADY)
        self._scrapers[scraper] = _Scraper(now, gap, gap if steady and long_enough else None)

    def next_scrape(self, now: float, after: float) -> tuple[float, float] | None:
        """The earliest scrape expected later than `after`, and that scraper's interval; None for none.

        A scraper that missed its expected scrape by half an interval (stopped, or changed its interval)
        is not expected again until it scrapes twice more at a steady interval.
        """
        expected = [
            (scraper.last + scraper.interval, scraper.interval)
            for scraper in self._scrapers.values()
            if scraper.interval is not None
            and scraper.last + scraper.interval > after
            and scraper.last + 1.5 * scraper.interval > now
        ]
        return min(expected, default=None)


class RenderAhead:
    """A thread that has the fleet render its series shortly before every scrape it expects."""

    def __init__(
        self,
        prepare: Callable[[], None],
        min_interval: float = MIN_INTERVAL,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        """Call `prepare` (render what changed, keep it for the scrape) ahead of the scrapes expected."""
        self._prepare = prepare
        self._clock = clock
        self._cadence = ScrapeCadence(min_interval)
        self._lock = threading.Lock()
        self._wake = threading.Event()
        self._stopping = threading.Event()
        self._thread: threading.Thread | None = None
        self.renders = 0  # renders ahead done
        self.passes = 0  # renders again after them, of what changed during the render before
        self.failures = 0  # renders ahead that raised (a worker restarting)
        self.skipped = 0  # expected scrapes not rendered ahead of, after render aheads with futile passes
        self.last_seconds = 0.0  # how long the last render ahead took (its first pass)
        self._scrapes = 0  # scrapes begun
        self._futile_in_a_row = 0  # render aheads, each with a futile pass, since one whose passes were not
        self._skip_until = float("-inf")  # scrapes expected before then are not rendered ahead of

    def scraped(self, scraper: str) -> None:
        """`scraper` began a scrape now."""
        with self._lock:
            self._cadence.scraped(scraper, self._clock())
            self._scrapes += 1
        self._wake.set()

    def start(self) -> None:
        """Begin rendering ahead of the scrapes expected."""
        self._thread = threading.Thread(target=self._run, name="render-ahead", daemon=True)
        self._thread.start()

    def stop(self) -> None:
        """Stop, waiting for a render under way."""
        self._stopping.set()
        self._wake.set()
        if self._thread is not None:
            self._thread.join()

    def _run(self) -> None:
        rendered_for = float("-inf")  # the expected scrape the last render ahead was for
        while not self._stopping.is_set():
            now = self._clock()
            with self._lock:
                # A scrape expected within a render's time of the last one (a pair of Prometheus
                # servers at nearly the same offset) finds that render still fresh: none of its own.
                expected = self._cadence.next_scrape(now, rendered_for + self.last_seconds + MARGIN)
            if expected is None:
                self._sleep(None)
                continue
            due, interval = expected
            # Begin twice as long before it as the last render took (this one may take longer, and
            # passes catch up with what changes meanwhile), and a margin; at most half an interval.
            begin = due - min(LEAD * self.last_seconds + MARGIN, interval / 2)
            if begin > now:
                self._sleep(begin - now)
                continue
            rendered_for = due
            if due < self._skip_until:
                self.skipped += 1
                continue
            with self._lock:
                scrapes = self._scrapes
            seconds = self._render()
            if seconds is not None:
                self.last_seconds = seconds
                self.renders += 1
                futile = self._render_until_scraped(seconds, scrapes, due)
                if futile is not None:
                    self._futile_in_a_row = self._futile_in_a_row + 1 if futile else 0
                if futile and self._futile_in_a_row >= FUTILE_IN_A_ROW:
                    # Whichever scrapers make them: a time, so that a scraper that stops leaves none behind.
                    self._skip_until = due + (SKIPPED_AFTER_FUTILE + 0.5) * interval

    def _render_until_scraped(self, seconds: float, scrapes: int, due: float) -> bool | None:
        """Render again what changed during the render before, until a scrape begins or it is `due`.

        True when a pass was futile: it took `FUTILE` times as long as the render ahead (`seconds`) or
        longer, and no more are begun; False when passes were made and none was; None when none was made.

        A pass is expected to take as long as the one before (`seconds`); it is not begun when it would
        end more than half of that after `due`. A scrape beginning at `due` would wait for the rest of the
        pass and then render what changed during all of it, where without the pass it renders what
        changed during the one before and since: less, once the pass would run past half its length (for
        passes as long as the one before; shorter ones would pay off a little later).
        """
        ahead, passes_before = seconds, self.passes
        while seconds >= MIN_PASS and not self._stopping.is_set() and self._clock() + seconds / 2 <= due:
            with self._lock:
                if self._scrapes != scrapes:
                    break
            passed = self._render()
            if passed is None:
                break
            self.passes += 1
            if passed >= FUTILE * ahead:
                log.debug("a pass took %.3f s after a render ahead of %.3f s: no gain", passed, ahead)
                return True
            seconds = passed
        return None if self.passes == passes_before else False

    def _sleep(self, seconds: float | None) -> None:
        """Until `seconds` have passed, a scrape began, or the thread is stopped."""
        self._wake.wait(seconds)
        self._wake.clear()

    def _render(self) -> float | None:
        """Render what changed: how long it took, or None when it failed."""
        started = self._clock()
        try:
            self._prepare()
        except Exception:  # a worker restarting: the scrape renders it all, as without this thread
            self.failures += 1
            log.debug("could not render the series ahead of a scrape", exc_info=True)
            return None
        return self._clock() - started


class RenderAheadCollector(Collector):
    """`overseer_exposition_renders_ahead_total`, the passes after them, and the seconds the last took."""

    def __init__(self, render_ahead: RenderAhead) -> None:
        """Tell of `render_ahead`."""
        self._render_ahead = render_ahead

    def collect(self) -> Iterator[Metric]:
        """The families, read now."""
        renders = CounterMetricFamily(
            "overseer_exposition_renders_ahead",
            "Renders of the fleet's series shortly before an expected scrape (result: done, failed), "
            "and expected scrapes not rendered ahead of after render aheads with futile passes (skipped).",
            labels=["result"],
        )
        renders.add_metric(["done"], float(self._render_ahead.renders))
        renders.add_metric(["failed"], float(self._render_ahead.failures))
        renders.add_metric(["skipped"], float(self._render_ahead.skipped))
        passes = CounterMetricFamily(
            "overseer_exposition_render_ahead_passes",
            "Renders again between a render ahead and its scrape, each of what changed during the last.",
        )
        passes.add_metric([], float(self._render_ahead.passes))
        seconds = GaugeMetricFamily(
            "overseer_exposition_render_ahead_seconds",
            "How long the last render ahead of a scrape took (its first pass).",
        )
        seconds.add_metric([], self._render_ahead.last_seconds)
        yield renders
        yield passes
        yield seconds
