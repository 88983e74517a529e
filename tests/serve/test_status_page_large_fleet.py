"""The status page of a large fleet in a real headless Chromium: a bounded number of rows, more on request.

The model is filled in this process through the real ingest (CDR payloads into `PayloadIngest`) and served
by the real HTTP server: 720 robots in six namespaces of 120, one robot of each namespace in ERROR and
named last, so that only the sort by level lists it first.
"""

from __future__ import annotations

import itertools
import time
from collections.abc import Callable, Iterator

import pytest
from playwright.sync_api import Browser, Page, Route, expect

from overseer.codec.cdr import WIRE_FORMAT, encode_diagnostic_array
from overseer.ingest.payload import PayloadIngest
from overseer.messages import DiagnosticArray, DiagnosticStatus
from overseer.model import FleetLimits, FleetModel
from overseer.serve.http import OverseerServer
from testbed.browser import error_free_page, expect_failed_request, open_page, wait_for_refresh
from testbed.model_server import serving

pytestmark = pytest.mark.servers  # a real HTTP server and Chromium

GROUPS = 6
PER_GROUP = 120
# What the page lists at first (serve/status_page/fleet.js): 100 rows a group, 500 on the page.
GROUP_ROWS = 100
PAGE_ROWS = 500


def robot_name(group: int, index: int) -> str:
    return f"g{group}/r{index:03d}"


@pytest.fixture(scope="module")
def server() -> Iterator[OverseerServer]:
    model = FleetModel(FleetLimits(max_robots=10_000, stale_after=3600, robot_timeout=3600))
    for group in range(GROUPS):
        for index in range(PER_GROUP):
            name = robot_name(group, index)
            level = 2 if index == PER_GROUP - 1 else 0
            array = DiagnosticArray(0, 0, "", (DiagnosticStatus(level, "/Laser", "scans", "", ()),))
            PayloadIngest(model, name, "dds", f"rt/{name}/diagnostics_agg", WIRE_FORMAT)(
                encode_diagnostic_array(array)
            )
    with serving(model) as server:
        yield server


@pytest.fixture
def page(browser: Browser) -> Iterator[Page]:
    with error_free_page(browser) as page:
        expect_failed_request(page, "/api/v1/maintenance")  # this server has no maintenance API: 404
        yield page


def listed_per_group(page: Page) -> dict[str, int]:
    counts: dict[str, int] = page.locator("details.group").evaluate_all(
        "groups => Object.fromEntries(groups.map("
        "g => [g.dataset.group, g.querySelectorAll('tr[data-robot]').length]))"
    )
    return counts


def test_a_large_fleet_lists_a_bounded_number_of_rows_and_counts_every_robot(
    page: Page, server: OverseerServer
) -> None:
    open_page(page, server.url + "/")
    assert listed_per_group(page) == {
        f"g{g}": GROUP_ROWS if g < PAGE_ROWS // GROUP_ROWS else 0 for g in range(6)
    }
    total = GROUPS * PER_GROUP
    expect(page.locator("#showing")).to_have_text(f"Showing {total} of {total} robots, {PAGE_ROWS} listed")
    expect(page.locator('[data-total="robots"]')).to_have_text(f"{total} robots")
    expect(page.locator('[data-total="ERROR"]')).to_have_text(str(GROUPS))
    expect(page.locator('details.group[data-group="g0"] > summary small')).to_have_text(
        f"{PER_GROUP} robots: 1 ERROR, {PER_GROUP - 1} OK"
    )
    expect(page.locator('details.group[data-group="g0"] .more-rows')).to_contain_text(
        f"{PER_GROUP - GROUP_ROWS} more robots not listed"
    )
    expect(page.locator('details.group[data-group="g5"] .more-rows')).to_contain_text(
        f"{PER_GROUP} robots not listed"
    )
    expect(page.locator('details.group[data-group="g5"] .more-rows button')).to_have_attribute(
        "aria-label", f"list all {PER_GROUP} robots of g5/"
    )


def test_the_sort_decides_which_robots_are_listed(page: Page, server: OverseerServer) -> None:
    in_trouble = robot_name(0, PER_GROUP - 1)  # last by name, first by level
    open_page(page, server.url + "/")
    rows = page.locator('details.group[data-group="g0"] tr[data-robot]')
    expect(rows.first).to_have_attribute("data-robot", robot_name(0, 0))
    expect(page.locator(f'tr[data-robot="{in_trouble}"]')).to_have_count(0)
    open_page(page, server.url + "/?sort=level")
    expect(rows.first).to_have_attribute("data-robot", in_trouble)
    expect(rows.first).to_have_attribute("data-state", "ERROR")


def test_list_all_lists_the_rest_of_a_group_takes_no_other_groups_rows_and_a_refresh_keeps_it(
    page: Page, server: OverseerServer
) -> None:
    open_page(page, server.url + "/")
    page.click('details.group[data-group="g0"] .more-rows button[data-list="all"]')
    expect(page.locator('details.group[data-group="g0"] tr[data-robot]')).to_have_count(PER_GROUP)
    expect(page.locator('details.group[data-group="g0"] .more-rows')).to_have_count(0)
    # the keyboard's place: the first robot the group had not listed
    assert page.evaluate("document.activeElement.textContent") == robot_name(0, GROUP_ROWS)
    page.click('details.group[data-group="g5"] .more-rows button[data-list="all"]')
    wait_for_refresh(page)
    listed = listed_per_group(page)
    assert listed == {"g0": PER_GROUP, "g1": 100, "g2": 100, "g3": 100, "g4": 100, "g5": PER_GROUP}, listed
    total = GROUPS * PER_GROUP
    expect(page.locator("#showing")).to_have_text(
        f"Showing {total} of {total} robots, {sum(listed.values())} listed"
    )


def test_listing_more_needs_no_new_read_of_the_fleet(page: Page, server: OverseerServer) -> None:
    open_page(page, server.url + "/")
    held: list[Route] = []

    def hold(route: Route) -> None:
        held.append(route)  # never answered: from now on the fleet's reads do not come back

    page.route("**/api/v1/robots", hold)
    page.click('details.group[data-group="g5"] .more-rows button[data-list="all"]')
    expect(page.locator('details.group[data-group="g5"] tr[data-robot]')).to_have_count(PER_GROUP)


def fleet_reads_a_second_long(page: Page, end: Callable[[Route], None]) -> list[float]:
    """Hold each of the page's reads of the fleet for a second, then `end` it; the list of when each began."""
    starts: list[float] = []

    def held(route: Route) -> None:
        starts.append(time.monotonic())
        time.sleep(1.0)
        end(route)

    page.route("**/api/v1/robots", held)
    return starts


def gaps_between(starts: list[float]) -> list[float]:
    return [later - earlier for earlier, later in itertools.pairwise(starts)]


def test_a_page_whose_reads_take_long_refreshes_less_often(page: Page, server: OverseerServer) -> None:
    """Reads of the fleet made to take a second: the page waits 4 s more."""
    starts = fleet_reads_a_second_long(page, Route.continue_)
    open_page(page, server.url + "/")
    page.wait_for_timeout(15_000)
    gaps = gaps_between(starts)
    assert len(gaps) >= 1, starts
    assert min(gaps) >= 4.5, gaps  # a second's read, then four times as long; 2 s apart when reads are quick


def test_a_read_that_failed_is_tried_again_at_the_usual_pace(page: Page, server: OverseerServer) -> None:
    """Reads that fail after a second: the page says so and tries again 2 s later, with no back-off."""
    open_page(page, server.url + "/")
    expect_failed_request(page, "/api/v1/robots")
    starts = fleet_reads_a_second_long(page, Route.abort)
    expect(page.locator("#error")).to_contain_text("cannot reach the exporter", timeout=10_000)
    page.wait_for_timeout(8_000)
    gaps = gaps_between(starts)
    assert len(gaps) >= 2, starts
    assert max(gaps) < 4.0, gaps  # a second's read, then 2 s; five seconds were it backed off
