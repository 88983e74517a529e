"""The status page of a fleet with an inventory, in a real headless Chromium against a live exporter.

One exporter reads the inventory file the module writes and follows a simulated fleet over DDS:
robot1 (tb4, site_a), robot2 (tb4, site_b), robot3 (mk2, site_a, a team whose name is HTML), robot4
(not listed), ghost (tb4, listed, never heard), gone/r1 (its publisher left) and quiet/r1 (its publisher
still there, silent). Model tb4 expects /Power/Robot Battery, which the simulator reports, and
/Arm/Gripper, which it does not.
"""

from __future__ import annotations

import re
import time
from collections.abc import Iterator
from typing import Any
from urllib.parse import parse_qs, urlsplit

import pytest
from playwright.sync_api import Browser, Page, expect

from overseer.codec.cdr import encode_diagnostic_array
from overseer.messages import DiagnosticArray, DiagnosticStatus
from testbed.browser import error_free_page, open_page
from testbed.dds_writer import raw_diagnostics_writer
from testbed.ports import fresh_domain_id
from testbed.processes import Exporter, running_exporter, running_simulator, wait_for

pytestmark = pytest.mark.servers  # every test here starts real servers or middleware

HOSTILE_TEAM = "<img src=x onerror=window.pwned=5>"
INVENTORY = f"""\
models:
  tb4:
    expected: [/Power/Robot Battery, /Arm/Gripper]
  mk2: {{}}
robots:
  robot1: {{model: tb4, labels: {{site: site_a, team: logistics}}}}
  robot2: {{model: tb4, labels: {{site: site_b, team: inspection}}}}
  robot3: {{model: mk2, labels: {{site: site_a, team: "{HOSTILE_TEAM}"}}}}
  ghost: {{model: tb4, labels: {{site: site_b}}}}
"""
UNLISTED = ["gone/r1", "quiet/r1", "robot4"]
DOWN = {"ghost": "never_heard", "gone/r1": "publisher_left", "quiet/r1": "silent"}


def fleet_ready(exporter: Exporter) -> bool:
    robots = {r["robot"]: r for r in exporter.get_json("/api/v1/robots")["robots"]}
    return set(robots) == {"robot1", "robot2", "robot3", "robot4", *DOWN} and all(
        robots[name]["down_reason"] == DOWN.get(name) for name in robots
    )


@pytest.fixture(scope="module")
def fleet(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Exporter]:
    """The module's exporter, its inventory and its fleet, once every robot is up or down as described.

    Robots are down after 3 s of silence (rather than 10 s), so that quiet/r1 is down soon.
    """
    tmp = tmp_path_factory.mktemp("inventory")
    inventory = tmp / "inventory.yml"
    inventory.write_text(INVENTORY, encoding="utf-8")
    domain = fresh_domain_id()
    quiet = encode_diagnostic_array(DiagnosticArray(0, 0, "", (DiagnosticStatus(0, "/Power", "ok", "", ()),)))
    with (
        running_exporter(
            tmp,
            domain,
            f"--inventory.file={inventory}",
            "--fleet.stale-after=3s",
            "--fleet.robot-timeout=3s",
        ) as exporter,
        running_simulator(tmp, domain, "--robots=4", "--rate=2"),
        raw_diagnostics_writer(domain, "rt/quiet/r1/diagnostics_agg") as writer,
    ):
        with running_simulator(tmp, domain, "--robots=1", "--namespace-prefix=gone/r"):
            wait_for(lambda: (exporter.robot("gone/r1") or {}).get("up"), 30, message="gone/r1")
        writer.wait_for_reader()
        for _ in range(4):  # heard, then silent with its publisher still there
            writer.write(quiet)
            time.sleep(0.25)
        wait_for(lambda: fleet_ready(exporter), 60, message="the fleet")
        yield exporter


@pytest.fixture
def page(browser: Browser) -> Iterator[Page]:
    """A fresh browser page (its own context); no script error allowed."""
    with error_free_page(browser) as page:
        yield page


def query_of(page: Page) -> dict[str, list[str]]:
    return parse_qs(urlsplit(page.url).query)


def shown_robots(page: Page) -> list[str]:
    robots: list[str] = page.locator("#groups tr[data-robot]").evaluate_all(
        "rows => rows.map(r => r.dataset.robot)"
    )
    return robots


def shown_groups(page: Page) -> list[list[Any]]:
    """[group, its title, its robots] of each group on the page, in order."""
    groups: list[list[Any]] = page.locator("details.group").evaluate_all(
        "groups => groups.map(g => [g.dataset.group, g.querySelector('.group-name').textContent,"
        " [...g.querySelectorAll('tr[data-robot]')].map(r => r.dataset.robot)])"
    )
    return groups


def choice(page: Page, selector: str) -> str:
    """The text of the option a select shows."""
    text: str = page.locator(selector).evaluate("s => s.selectedOptions[0].textContent")
    return text


def test_group_by_site_then_by_model_puts_each_robot_under_its_value_and_the_rest_apart(
    page: Page, fleet: Exporter
) -> None:
    open_page(page, fleet.url + "/")
    options = page.locator("#group option").all_text_contents()
    assert options == ["namespace", "model", "site", "team"]
    page.select_option("#group", "site")
    expect(page.locator("details.group").first).to_have_attribute("data-group", "site_a")
    assert query_of(page) == {"group": ["site"]}
    assert shown_groups(page) == [
        ["site_a", "site=site_a", ["robot1", "robot3"]],
        ["site_b", "site=site_b", ["ghost", "robot2"]],
        ["", "(no site)", UNLISTED],
    ]
    labels = page.locator('tr[data-robot="robot1"] td.labels .label').all_text_contents()
    assert labels == ["model=tb4", "site=site_a", "team=logistics"]

    page.select_option("#group", "model")
    expect(page.locator("details.group").first).to_have_attribute("data-group", "mk2")
    assert query_of(page) == {"group": ["model"]}
    assert shown_groups(page) == [
        ["mk2", "model=mk2", ["robot3"]],
        ["tb4", "model=tb4", ["ghost", "robot1", "robot2"]],
        ["", "(no model)", UNLISTED],
    ]
    expect(page.locator('details.group[data-group="tb4"] > summary')).to_contain_text("3 robots")


def test_a_label_filter_shows_only_the_robots_with_that_label_and_their_components(
    page: Page, fleet: Exporter
) -> None:
    open_page(page, fleet.url + "/")
    site = 'select[data-label="site"]'
    assert page.locator(f"{site} option").all_text_contents() == ["all", "site_a", "site_b", "(no site)"]
    page.select_option(site, "site_a")
    expect(page.locator("#showing")).to_have_text("Showing 2 of 7 robots")
    assert shown_robots(page) == ["robot1", "robot3"]
    assert query_of(page) == {"label": ["site=site_a"]}

    page.select_option('select[data-label="model"]', "tb4")
    expect(page.locator("#showing")).to_have_text("Showing 1 of 7 robots")
    assert shown_robots(page) == ["robot1"]
    assert query_of(page) == {"label": ["model=tb4", "site=site_a"]}
    page.fill("#search", "no scans")  # every simulated robot has it: only robot1's are listed
    expect(page.locator("#matches-count")).to_have_text("1 components match")
    matches = page.locator("#matches-rows tr").evaluate_all("rows => rows.map(r => r.dataset.robot)")
    assert matches == ["robot1"]

    page.fill("#search", "")
    page.select_option('select[data-label="model"]', "all")
    page.select_option(site, "(no site)")
    expect(page.locator("#showing")).to_have_text("Showing 3 of 7 robots")
    assert shown_robots(page) == UNLISTED
    assert query_of(page) == {"label": ["site="]}

    page.select_option(site, "all")
    page.select_option('select[data-label="team"]', HOSTILE_TEAM)  # a label's value is text, never HTML
    expect(page.locator("#showing")).to_have_text("Showing 1 of 7 robots")
    assert shown_robots(page) == ["robot3"]
    expect(page.locator('tr[data-robot="robot3"] .label[data-label="team"]')).to_have_text(
        f"team={HOSTILE_TEAM}"
    )
    assert page.locator("main img").count() == 0
    assert page.evaluate("window.pwned") is None


def test_a_listed_robot_never_heard_says_so_instead_of_a_time(page: Page, fleet: Exporter) -> None:
    open_page(page, fleet.url + "/")
    row = page.locator('#groups tr[data-robot="ghost"]')
    expect(row).to_have_attribute("data-down-reason", "never_heard")
    expect(row.locator("td").last).to_have_text("never heard: listed in the inventory")
    row.locator("a").click()
    page.wait_for_selector("body[data-view=robot]")
    facts = page.locator("#robot-facts")
    expect(facts).to_contain_text("never heard: listed in the inventory · 2 components")
    assert "ago" not in (facts.text_content() or "") and "last message" not in (facts.text_content() or "")
    expect(facts.locator(".label")).to_have_text(["model=tb4", "site=site_b"])
    stand_ins = page.locator('#tree [data-reported="false"]').evaluate_all(
        "nodes => nodes.map(n => n.dataset.component)"
    )
    assert stand_ins == ["/Arm/Gripper", "/Power/Robot Battery"]


def test_a_down_robot_says_why_its_publisher_left_or_it_went_silent(page: Page, fleet: Exporter) -> None:
    ago = r"\d+ (s|min)"  # a slow machine may get here minutes after the fleet was ready
    open_page(page, fleet.url + "/")
    gone = page.locator('#groups tr[data-robot="gone/r1"]')
    expect(gone).to_have_attribute("data-down-reason", "publisher_left")
    expect(gone.locator("td").last).to_have_text(
        re.compile(rf"^down: publisher left, last message {ago} ago$")
    )
    quiet = page.locator('#groups tr[data-robot="quiet/r1"]')
    expect(quiet).to_have_attribute("data-down-reason", "silent")
    expect(quiet.locator("td").last).to_have_text(re.compile(rf"^down: silent for {ago}$"))
    open_page(page, fleet.url + "/?robot=quiet%2Fr1", view="robot")
    expect(page.locator("#robot-facts")).to_have_text(
        re.compile(rf"^down: silent for {ago} · dds · last message .+ \({ago} ago\) · 1 components")
    )


def test_an_expected_component_not_reported_is_marked_and_has_no_update_time(
    page: Page, fleet: Exporter
) -> None:
    open_page(page, fleet.url + "/?robot=robot1", view="robot")
    leaves = page.locator("#tree .leaf").evaluate_all(
        """leaves => Object.fromEntries(leaves.map(l => [
          l.querySelector("[data-component]").dataset.component,
          {tags: [...l.querySelectorAll(".tag")].map(t => t.textContent),
           message: l.querySelector(".message").textContent,
           updated: l.querySelector(".updated")?.textContent ?? null}]))"""
    )
    assert leaves["/Arm/Gripper"] == {
        "tags": ["expected", "not reported"],
        "message": "expected, not reported",
        "updated": None,
    }
    assert leaves["/Power/Robot Battery"]["tags"] == ["expected"]
    assert re.fullmatch(r"\d+ s ago", leaves["/Power/Robot Battery"]["updated"])
    assert leaves["/Temp/Sensor1"]["tags"] == []
    gripper = page.locator('#tree [data-component="/Arm/Gripper"]')
    expect(gripper).to_have_attribute("data-state", "STALE")
    expect(gripper).to_have_attribute("data-reported", "false")
    expect(page.locator('#tree details[data-path="/Arm"]')).to_have_attribute("open", "")


def test_the_label_filter_and_grouping_deep_link_round_trips(page: Page, fleet: Exporter) -> None:
    link = "/?sort=level&label=site=site_a&label=team=logistics&group=model"
    open_page(page, fleet.url + link)
    assert choice(page, 'select[data-label="site"]') == "site_a"
    assert choice(page, 'select[data-label="team"]') == "logistics"
    assert choice(page, 'select[data-label="model"]') == "all"
    assert choice(page, "#group") == "model"
    expect(page.locator("#sort")).to_have_value("level")
    assert shown_groups(page) == [["tb4", "model=tb4", ["robot1"]]]
    wanted = {"sort": ["level"], "label": ["site=site_a", "team=logistics"], "group": ["model"]}

    page.click('#groups tr[data-robot="robot1"] a')
    page.wait_for_selector("body[data-view=robot]")
    assert query_of(page) == {"robot": ["robot1"]}
    page.click("#back")
    page.wait_for_selector("body[data-view=fleet]")
    assert query_of(page) == wanted
    assert shown_robots(page) == ["robot1"]
    page.reload()
    page.wait_for_selector("body[data-view=fleet]")
    assert query_of(page) == wanted
    assert choice(page, 'select[data-label="team"]') == "logistics"
    assert shown_groups(page) == [["tb4", "model=tb4", ["robot1"]]]

    open_page(page, fleet.url + "/?robot=robot2", view="robot")  # a robot's label leads to its fleet
    page.click('#robot-facts a:has(.label[data-label="site"])')
    page.wait_for_selector("body[data-view=fleet]")
    assert query_of(page) == {"label": ["site=site_b"]}
    assert shown_robots(page) == ["ghost", "robot2"]

    open_page(page, fleet.url + "/?label=site=site_z&group=rack")  # labels no robot has are kept
    assert choice(page, 'select[data-label="site"]') == "site_z"
    assert choice(page, "#group") == "rack"
    expect(page.locator("#showing")).to_have_text("Showing 0 of 7 robots")


def test_clear_filters_forgets_the_labels_and_the_grouping(page: Page, fleet: Exporter) -> None:
    open_page(page, fleet.url + "/?label=site=site_b&group=site")
    assert shown_robots(page) == ["ghost", "robot2"]
    page.click("#clear")
    expect(page.locator("#showing")).to_have_text("Showing 7 of 7 robots")
    assert page.url == fleet.url + "/"
    assert choice(page, 'select[data-label="site"]') == "all"
    assert choice(page, "#group") == "namespace"
