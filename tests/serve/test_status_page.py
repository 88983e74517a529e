"""The fleet status page in a real headless Chromium (through Playwright) against a live exporter.

One exporter follows a simulated fleet over DDS for the module: robot1 (WARN) and robot2 (ERROR, its
/Motor/Motor1 set by an event), site_a/r1..r3 (ERROR and WARN each), and a robot whose name, components
and messages are HTML (published from the test). Tests that change the fleet run exporters of their own.
"""

from __future__ import annotations

import re
import threading
import urllib.request
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from urllib.parse import parse_qs, quote, urlsplit

import pytest
from playwright.sync_api import Browser, Page, expect

from overseer.codec.cdr import encode_diagnostic_array
from overseer.messages import DiagnosticArray, DiagnosticStatus
from testbed.browser import error_free_page, expect_failed_request, open_page, wait_for_refresh
from testbed.dds_writer import raw_diagnostics_writer
from testbed.ports import fresh_domain_id
from testbed.processes import Exporter, running_exporter, running_simulator, wait_for

pytestmark = pytest.mark.servers  # every test here starts real servers or middleware


HOSTILE_ROBOT = "evil/<img/src=x/onerror=window.pwned=1>&amp;%2F"
HOSTILE_COMPONENT = '/Evil/"><img src=x onerror="window.pwned=2">'
HOSTILE_MESSAGE = "<b>bold</b> &lt;script&gt;window.pwned=3&lt;/script&gt;"
HOSTILE_HARDWARE_ID = "<script>window.pwned=4</script>"
SITE_ROBOTS = ["site_a/r1", "site_a/r2", "site_a/r3"]
ALL_ROBOTS = {
    "robot1": "WARN",
    "robot2": "ERROR",
    **dict.fromkeys(SITE_ROBOTS, "ERROR"),
    HOSTILE_ROBOT: "WARN",
}


@contextmanager
def hostile_robot(domain: int) -> Iterator[None]:
    """A robot whose name, component, message and hardware_id are HTML, publishing twice a second."""
    payload = encode_diagnostic_array(
        DiagnosticArray(
            0,
            0,
            "",
            (
                DiagnosticStatus(
                    1, HOSTILE_COMPONENT, HOSTILE_MESSAGE, HOSTILE_HARDWARE_ID, (("<i>k</i>", "<u>v</u>"),)
                ),
                DiagnosticStatus(0, "/Evil", "<em>group</em>", "", ()),
            ),
        )
    )
    stop = threading.Event()
    with raw_diagnostics_writer(domain, f"rt/{HOSTILE_ROBOT}/diagnostics_agg") as writer:

        def publish() -> None:
            while not stop.wait(0.5):
                writer.write(payload)

        thread = threading.Thread(target=publish, daemon=True)
        thread.start()
        try:
            yield
        finally:
            stop.set()
            thread.join()


def fleet_ready(exporter: Exporter) -> bool:
    robots = {r["robot"]: r for r in exporter.get_json("/api/v1/robots")["robots"]}
    return set(robots) == set(ALL_ROBOTS) and all(
        r["up"] and r["state"] == ALL_ROBOTS[name] for name, r in robots.items()
    )


@pytest.fixture(scope="module")
def fleet(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Exporter]:
    """The module's exporter with its simulated fleet, once every robot is up at its expected level."""
    tmp = tmp_path_factory.mktemp("fleet")
    domain = fresh_domain_id()
    with (
        running_exporter(tmp, domain, f"--events.path={tmp / 'events.db'}") as exporter,
        running_simulator(
            tmp, domain, "--robots=2", "--warn=1", "--error=0", "--event=0:robot2:/Motor/Motor1:ERROR"
        ),
        running_simulator(tmp, domain, "--robots=3", "--namespace-prefix=site_a/r"),
        hostile_robot(domain),
    ):
        wait_for(lambda: fleet_ready(exporter), 60, message="the fleet")
        yield exporter


@pytest.fixture
def page(browser: Browser) -> Iterator[Page]:
    """A fresh browser page (its own context: no state shared between tests); no script error allowed."""
    with error_free_page(browser) as page:
        yield page


def shown_robots(page: Page) -> list[str]:
    robots: list[str] = page.locator("#groups tr[data-robot]").evaluate_all(
        "rows => rows.map(r => r.dataset.robot)"
    )
    return robots


def query_of(page: Page) -> dict[str, list[str]]:
    return parse_qs(urlsplit(page.url).query)


def test_fleet_view_shows_each_robot_colored_by_level_and_counts_per_level(
    page: Page, fleet: Exporter
) -> None:
    open_page(page, fleet.url + "/")
    rows = page.locator("#groups tr[data-robot]").evaluate_all(
        "rows => rows.map(r => [r.dataset.robot, r.dataset.state, r.querySelector('.badge').className])"
    )
    assert {robot: state for robot, state, _ in rows} == ALL_ROBOTS
    assert all(badge == f"badge {state}" for _, state, badge in rows)
    expect(page.locator('[data-total="ERROR"]')).to_have_text("4")
    expect(page.locator('[data-total="WARN"]')).to_have_text("2")
    expect(page.locator('[data-total="OK"]')).to_have_text("0")
    expect(page.locator('[data-total="down"]')).to_have_text("down 0")
    expect(page.locator("#showing")).to_have_text("Showing 6 of 6 robots")


def test_the_page_has_its_icon_and_the_icon_is_where_browsers_look_for_it_unasked(
    page: Page, fleet: Exporter
) -> None:
    icons: list[tuple[str, int, str]] = []
    page.on(
        "response",
        lambda response: (
            icons.append((response.url, response.status, response.headers["content-type"]))
            if "favicon" in response.url
            else None
        ),
    )
    open_page(page, fleet.url + "/")  # the page fails on any console error: a missing icon is one
    expect(page.locator("link[rel=icon]")).to_have_attribute("href", "static/favicon.svg")
    with urllib.request.urlopen(fleet.url + "/favicon.ico", timeout=5) as answer:
        assert (answer.status, answer.headers["Content-Type"]) == (200, "image/svg+xml")
        assert answer.read().startswith(b"<svg")
    assert all(status == 200 and kind == "image/svg+xml" for _, status, kind in icons), icons


def test_robots_are_grouped_by_namespace_prefix(page: Page, fleet: Exporter) -> None:
    open_page(page, fleet.url + "/")
    groups = page.locator("details.group").evaluate_all(
        "groups => groups.map(g => [g.dataset.group, [...g.querySelectorAll('tr[data-robot]')]"
        ".map(r => r.dataset.robot)])"
    )
    assert groups == [["evil", [HOSTILE_ROBOT]], ["", ["robot1", "robot2"]], ["site_a", SITE_ROBOTS]]
    expect(page.locator('details.group[data-group="site_a"] > summary')).to_contain_text("3 robots: 3 ERROR")


def test_level_filter_narrows_robots_and_lists_those_components_across_the_fleet(
    page: Page, fleet: Exporter
) -> None:
    open_page(page, fleet.url + "/")
    page.click('button.chip[data-level="ERROR"]')
    expect(page.locator('button.chip[data-level="ERROR"]')).to_have_attribute("aria-pressed", "true")
    expect(page.locator("#showing")).to_have_text("Showing 4 of 6 robots")
    assert query_of(page) == {"level": ["ERROR"]}
    assert sorted(shown_robots(page)) == ["robot2", *SITE_ROBOTS]
    matches = page.locator("#matches-rows tr").evaluate_all(
        "rows => rows.map(r => [r.dataset.robot, r.dataset.component, r.dataset.state])"
    )
    assert ["robot2", "/Motor/Motor1", "ERROR"] in matches
    assert {state for _, _, state in matches} == {"ERROR"}
    assert ["site_a/r1", "/Laser/Laser2", "ERROR"] in matches
    page.click('button.chip[data-level="WARN"]')
    expect(page.locator("#showing")).to_have_text("Showing 6 of 6 robots")
    assert query_of(page) == {"level": ["ERROR,WARN"]}


def test_search_finds_robots_by_name_and_by_their_components_messages(page: Page, fleet: Exporter) -> None:
    open_page(page, fleet.url + "/")
    page.fill("#search", "no scans")  # the message of site_a robots' /Laser/Laser2 only
    expect(page.locator("#showing")).to_have_text("Showing 3 of 6 robots")
    assert query_of(page) == {"q": ["no scans"]}
    assert shown_robots(page) == SITE_ROBOTS
    messages = page.locator("#matches-rows tr td:nth-child(5)").all_text_contents()
    assert messages == ["No scans received"] * 3
    page.fill("#search", "site_a/r2")
    expect(page.locator("#showing")).to_have_text("Showing 1 of 6 robots")
    assert shown_robots(page) == ["site_a/r2"]
    page.fill("#search", "motor1")  # a component name: every simulated robot has one
    expect(page.locator("#showing")).to_have_text("Showing 5 of 6 robots")
    expect(
        page.locator('#matches-rows tr[data-robot="robot2"][data-component="/Motor/Motor1"]')
    ).to_have_attribute("data-state", "ERROR")


def test_sort_orders_robots_worst_first_and_groups_follow(page: Page, fleet: Exporter) -> None:
    open_page(page, fleet.url + "/")
    assert shown_robots(page) == [HOSTILE_ROBOT, "robot1", "robot2", *SITE_ROBOTS]
    page.select_option("#sort", "level")
    expect(page).to_have_url(re.compile(r"\?sort=level$"))
    expect(page.locator("#groups tr[data-robot]").first).to_have_attribute("data-robot", "robot2")
    assert shown_robots(page) == ["robot2", "robot1", *SITE_ROBOTS, HOSTILE_ROBOT]


def test_drilling_into_a_robot_shows_its_component_tree_with_worst_levels_rolled_up(
    page: Page, fleet: Exporter
) -> None:
    open_page(page, fleet.url + "/")
    page.click('#groups tr[data-robot="site_a/r2"] a')
    page.wait_for_selector("body[data-view=robot]")
    assert query_of(page) == {"robot": ["site_a/r2"]}
    assert "robot=site_a%2Fr2" in page.url
    expect(page.locator("#robot-title")).to_have_text("ERROR site_a/r2: ERROR")
    components = page.locator("#tree [data-component]").evaluate_all(
        "nodes => nodes.map(n => [n.dataset.component, n.dataset.state])"
    )
    assert len(components) == 15
    assert ["/Laser/Laser2", "ERROR"] in components and ["/Camera/Cam2", "WARN"] in components
    folders = page.locator("#tree details.folder").evaluate_all(
        "nodes => nodes.map(n => [n.dataset.path, n.dataset.state, n.open])"
    )
    assert folders == [
        ["/Camera", "WARN", True],
        ["/Laser", "ERROR", True],
        ["/Motor", "OK", False],
        ["/Power", "OK", False],
        ["/Temp", "OK", False],
    ]
    text = page.locator("#tree").text_content() or ""
    assert "Charge OK" in text and "Low charge" not in text
    page.go_back()
    page.wait_for_selector("body[data-view=fleet]")
    expect(page.locator("#showing")).to_have_text("Showing 6 of 6 robots")


def test_deep_links_open_the_filtered_fleet_and_a_robot_directly(page: Page, fleet: Exporter) -> None:
    expect_failed_request(page, "/api/v1/robots/nobody")  # a link to a robot the exporter does not know
    open_page(page, fleet.url + "/?level=ERROR,WARN&q=laser&sort=level")
    expect(page.locator("#search")).to_have_value("laser")
    expect(page.locator("#sort")).to_have_value("level")
    pressed = page.locator('button.chip[aria-pressed="true"]').evaluate_all(
        "b => b.map(c => c.dataset.level)"
    )
    assert pressed == ["ERROR", "WARN"]
    # both filters apply to components: only site_a's robots have a laser that is not OK
    assert shown_robots(page) == SITE_ROBOTS
    matches = page.locator("#matches-rows tr").evaluate_all("rows => rows.map(r => r.dataset.component)")
    assert sorted(set(matches)) == ["/Laser", "/Laser/Laser2"]
    open_page(page, f"{fleet.url}/?robot={quote('site_a/r3', safe='')}", view="robot")
    expect(page.locator("#robot-title")).to_have_text("ERROR site_a/r3: ERROR")
    open_page(page, fleet.url + "/#site_a%2Fr1", view="robot")  # the first page's links still work
    expect(page.locator("#robot-title")).to_have_text("ERROR site_a/r1: ERROR")
    assert query_of(page) == {"robot": ["site_a/r1"]}
    open_page(page, f"{fleet.url}/?robot=nobody", view="robot")
    expect(page.locator("#robot-title")).to_have_text("nobody: unknown robot")


def test_auto_refresh_keeps_the_filter_the_scroll_and_the_folders(browser: Browser, fleet: Exporter) -> None:
    context = browser.new_context(viewport={"width": 900, "height": 250})
    try:
        page = context.new_page()
        open_page(page, fleet.url + "/?level=ERROR&sort=level")
        page.click('details.group[data-group="site_a"] > summary')  # closes it
        page.evaluate("window.scrollTo(0, 120)")
        wait_for_refresh(page)
        wait_for_refresh(page)
        assert query_of(page) == {"level": ["ERROR"], "sort": ["level"]}
        assert page.evaluate("window.scrollY") == 120
        assert page.locator('details.group[data-group="site_a"]').evaluate("d => d.open") is False
        assert shown_robots(page) == ["robot2", *SITE_ROBOTS]
        expect(page.locator('button.chip[data-level="ERROR"]')).to_have_attribute("aria-pressed", "true")

        open_page(page, f"{fleet.url}/?robot=site_a%2Fr1", view="robot")
        page.click('#tree details[data-path="/Laser"] > summary')  # open by default (ERROR): close it
        page.click('#tree details[data-path="/Power"] > summary')  # closed by default (OK): open it
        wait_for_refresh(page)
        wait_for_refresh(page)
        opened = page.locator("#tree details.folder").evaluate_all(
            "nodes => Object.fromEntries(nodes.map(n => [n.dataset.path, n.open]))"
        )
        assert opened == {"/Camera": True, "/Laser": False, "/Motor": False, "/Power": True, "/Temp": False}
    finally:
        context.close()


def test_hostile_names_and_messages_are_rendered_as_text(page: Page, fleet: Exporter) -> None:
    open_page(page, fleet.url + "/?q=%3Cimg")
    expect(page.locator("#showing")).to_have_text("Showing 1 of 6 robots")
    row = page.locator("#groups tr[data-robot]")
    expect(row).to_have_attribute("data-robot", HOSTILE_ROBOT)
    expect(row.locator("a")).to_have_text(HOSTILE_ROBOT)
    matches = page.locator("#matches-rows tr").evaluate_all("rows => rows.map(r => r.dataset.component)")
    assert HOSTILE_COMPONENT in matches
    assert HOSTILE_MESSAGE in (page.locator("#matches-rows").text_content() or "")
    row.locator("a").click()
    page.wait_for_selector("body[data-view=robot]")
    assert query_of(page) == {"robot": [HOSTILE_ROBOT]}
    expect(page.locator("#robot-title")).to_have_text(f"WARN {HOSTILE_ROBOT}: WARN")
    tree = page.locator("#tree").text_content() or ""
    for text in (
        '"><img src=x onerror="window.pwned=2">',
        HOSTILE_MESSAGE,
        HOSTILE_HARDWARE_ID,
        "<i>k</i>=<u>v</u>",
        "<em>group</em>",
    ):
        assert text in tree
    assert page.locator("main img, main script, main b, main i, main u, main em").count() == 0
    assert page.evaluate("window.pwned") is None
    open_page(page, f"{fleet.url}/?robot={quote(HOSTILE_ROBOT, safe='')}", view="robot")  # its deep link
    expect(page.locator("#robot-title")).to_have_text(f"WARN {HOSTILE_ROBOT}: WARN")


def test_tree_rolls_up_the_worst_level_by_severity_not_the_numeric_maximum(
    page: Page, fleet: Exporter
) -> None:
    open_page(page, fleet.url + "/")
    states = page.evaluate(
        """async () => {
          const {buildTree} = await import("./static/tree.js");
          const c = (name, state) => ({name, state, hardware_id: "", message: "", values: []});
          const tree = buildTree([c("/A/x", "STALE"), c("/A/y", "WARN"), c("/B/x", "STALE"), c("/B/y", "OK"),
                                  c("/C", "OK"), c("/C/D/e", "ERROR"), c("/C/D/f", "STALE"), c("top", "OK")]);
          const out = {};
          const walk = (node) => {
            for (const child of node.children.values()) { out[child.path] = child.state; walk(child); }
          };
          walk(tree);
          return out;
        }"""
    )
    assert states == {
        "/A": "WARN",  # WARN outranks STALE although STALE is 3 and WARN 1
        "/A/x": "STALE",
        "/A/y": "WARN",
        "/B": "STALE",
        "/B/x": "STALE",
        "/B/y": "OK",
        "/C": "ERROR",
        "/C/D": "ERROR",
        "/C/D/e": "ERROR",
        "/C/D/f": "STALE",
        "/top": "OK",
    }


def test_timeline_says_no_history_when_the_exporter_has_none_faked_older_exporter(
    page: Page, fleet: Exporter
) -> None:
    page.route("**/api/v1/events*", lambda route: route.fulfill(status=404, body='{"error": "no such path"}'))
    expect_failed_request(page, "/api/v1/events")
    open_page(page, f"{fleet.url}/?robot=robot1", view="robot")
    expect(page.locator("#timeline-note")).to_have_text("no history: this exporter keeps no event history")
    assert page.locator("#timeline-events li").count() == 0
    expect(page.locator("#robot-title")).to_have_text("WARN robot1: WARN")  # the rest of the view works


def test_timeline_shows_a_change_made_during_the_test(page: Page, tmp_path: Path, dds_domain: int) -> None:
    with (
        running_exporter(tmp_path, dds_domain, f"--events.path={tmp_path / 'events.db'}") as exporter,
        running_simulator(tmp_path, dds_domain, "--robots=1", "--event=20:robot1:/Temp/Sensor1:ERROR"),
    ):
        wait_for(lambda: exporter.robot("robot1"), 30, message="robot1")
        open_page(page, exporter.url + "/?robot=robot1", view="robot")
        sensor = page.locator('#tree [data-component="/Temp/Sensor1"]')
        # the page is up before the change (a machine too slow for that fails here, not later)
        assert sensor.get_attribute("data-state") == "OK", "the page opened after the change it must see"
        sensor_changes = '#timeline-events li[data-kind="level"][data-component="/Temp/Sensor1"]'
        assert page.locator(sensor_changes).count() == 0
        change = page.locator(sensor_changes + '[data-state="ERROR"]')
        expect(change).to_have_count(1, timeout=40_000)
        expect(change.locator(".change")).to_have_text("OK → ERROR")
        expect(sensor).to_have_attribute("data-state", "ERROR")

        others = page.locator('#timeline-events li:not([data-component="/Temp/Sensor1"])')
        assert others.count() > 0  # the robot's other components appeared too
        page.click('#tree button[data-history="/Temp/Sensor1"]')  # narrow the history to that component
        assert query_of(page) == {"robot": ["robot1"], "component": ["/Temp/Sensor1"]}
        expect(others).to_have_count(0)
        expect(change).to_have_count(1)
        expect(page.locator("#timeline-component")).to_contain_text("only /Temp/Sensor1")

        folder = page.locator('#tree details[data-path="/Temp"]')
        was_open = folder.evaluate("d => d.open")
        page.click('#tree details[data-path="/Temp"] > summary button[data-history="/Temp"]')
        assert query_of(page) == {"robot": ["robot1"], "component": ["/Temp"]}
        expect(page.locator('#timeline-events li[data-component="/Temp"]').first).to_be_attached()
        expect(change).to_have_count(1)  # "/Temp" narrows to every component whose name contains it
        assert folder.evaluate("d => d.open") == was_open
        page.click("#timeline-all")
        assert query_of(page) == {"robot": ["robot1"]}
        expect(others.first).to_be_attached()


def test_status_page_reports_an_exporter_that_went_away(page: Page, tmp_path: Path, dds_domain: int) -> None:
    expect_failed_request(page, "/api/v1/")  # once it is gone
    with running_exporter(tmp_path, dds_domain, f"--events.path={tmp_path / 'events.db'}") as exporter:
        open_page(page, exporter.url + "/")
        expect(page.locator("#error")).to_have_text("")
        exporter.stop()
        expect(page.locator("#error")).to_contain_text("cannot reach the exporter", timeout=15_000)
