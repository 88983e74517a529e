"""Status page: time to first render in a real headless Chromium, at 1,000 robots x 50 components.

`--robots 1000,10000` measures other fleet sizes (each held to the same target).

The exporter's model is filled through the real ingest (CDR payloads into `PayloadIngest`, as the DDS
source hands them over), since one simulator process cannot publish 50,000 components on two cores; the
real HTTP server serves it on loopback, and Debian's Chromium, driven by Playwright, loads the page.
Time to first render is the page's own performance mark `overseer-first-render` (set once the first
data is on screen), counted from navigation start; each figure is the median of several fresh loads.
The 100-robot fleet gives the ratio that shows how the page scales.
"""

from __future__ import annotations

import argparse
import statistics
import time
import urllib.request

from playwright.sync_api import Browser

from bench.common import Row, emit
from overseer.codec.cdr import WIRE_FORMAT, encode_diagnostic_array
from overseer.ingest.payload import PayloadIngest
from overseer.messages import DiagnosticArray
from overseer.model import FleetLimits, FleetModel
from overseer.simulator.design import aggregated_statuses, initial_levels, leaf_components
from testbed.browser import headless_chromium
from testbed.model_server import serving

LEAVES = 50
SITES = 10
LOADS = 7
TARGET_MS = 1000


def fill(model: FleetModel, robots: int) -> None:
    """`robots` robots of `LEAVES` leaves (plus group statuses) each, over `SITES` namespaces."""
    leaves = leaf_components(LEAVES)
    for index in range(robots):
        levels = initial_levels(leaves, index % 3, index % 2)
        array = DiagnosticArray(0, 0, "", tuple(aggregated_statuses(leaves, levels, set())))
        name = f"site{index % SITES}/robot{index}"
        ingest = PayloadIngest(model, name, "dds", f"rt/{name}/diagnostics_agg", WIRE_FORMAT)
        ingest(encode_diagnostic_array(array))


def first_render_ms(browser: Browser, url: str, view: str, loads: int = LOADS) -> float:
    """Median time from navigation start to the page's first render, over `loads` fresh loads."""
    timings = []
    for _ in range(loads):
        context = browser.new_context(viewport={"width": 1280, "height": 900})
        page = context.new_page()
        page.goto(url)
        page.wait_for_selector(f"body[data-view={view}]", timeout=60_000)
        timings.append(
            float(page.evaluate("performance.getEntriesByName('overseer-first-render')[0].startTime"))
        )
        context.close()
    return statistics.median(timings)


def get_ms(url: str, repeats: int = 7) -> tuple[float, int]:
    """Median latency of GET `url`, and its body size."""
    timings, size = [], 0
    for _ in range(repeats):
        started = time.perf_counter()
        with urllib.request.urlopen(url, timeout=60) as response:
            size = len(response.read())
        timings.append((time.perf_counter() - started) * 1000)
    return statistics.median(timings), size


def measure(browser: Browser, robots: int) -> dict[str, float]:
    """Figures of one fleet size: page first renders, and the JSON the page reads."""
    model = FleetModel(FleetLimits(max_robots=100_000, stale_after=3600, robot_timeout=3600))
    fill(model, robots)
    with serving(model) as server:
        figures = {
            "fleet": first_render_ms(browser, server.url + "/", "fleet"),
            "filtered": first_render_ms(
                browser, server.url + "/?level=ERROR,WARN&q=laser&sort=level", "fleet"
            ),
            "robot": first_render_ms(browser, server.url + "/?robot=site1%2Frobot1", "robot"),
        }
        figures["robots_ms"], figures["robots_bytes"] = get_ms(server.url + "/api/v1/robots")
        figures["search_ms"], figures["search_bytes"] = get_ms(
            server.url + "/api/v1/components?q=no%20scans&limit=200"
        )
        return figures


def size_rows(robots: int, figures: dict[str, float]) -> list[Row]:
    """The rows of one fleet size: first renders held to the target, and the JSON the page reads."""
    label = f"{robots} robots x {LEAVES} components"
    views = (
        ("fleet", "fleet view"),
        ("filtered", "filtered fleet view (level, search, sort)"),
        ("robot", "robot view"),
    )
    rows = [
        Row(
            "status page",
            f"{label}: {name}, first render",
            figures[key],
            "ms",
            f"<= {TARGET_MS}",
            figures[key] <= TARGET_MS,
        )
        for key, name in views
    ]
    components = robots * LEAVES // 1000
    return [
        *rows,
        Row("status page", f"{label}: GET /api/v1/robots", figures["robots_ms"], "ms"),
        Row("status page", f"{label}: /api/v1/robots size", figures["robots_bytes"] / 1e3, "kB"),
        Row(
            "status page",
            f"{label}: GET /api/v1/components search ({components}k components)",
            figures["search_ms"],
            "ms",
        ),
        Row(
            "status page",
            f"{label}: /api/v1/components answer size (limit 200)",
            figures["search_bytes"] / 1e3,
            "kB",
        ),
    ]


def main() -> None:
    """Measure each fleet size asked for (100 and 1,000 robots of 50 components by default)."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0] if __doc__ else None)
    parser.add_argument("--robots", default="100,1000", help="comma-separated fleet sizes (default 100,1000)")
    sizes = sorted(int(size) for size in parser.parse_args().robots.split(","))
    with headless_chromium() as browser:
        figures = {robots: measure(browser, robots) for robots in sizes}
    rows = [row for robots in sizes for row in size_rows(robots, figures[robots])]
    smallest, largest = sizes[0], sizes[-1]
    if largest != smallest:
        ratio = figures[largest]["fleet"] / figures[smallest]["fleet"]
        rows.append(Row("status page", f"fleet view first render, {largest} / {smallest} robots", ratio, "x"))
    emit(rows)


if __name__ == "__main__":
    main()
