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


def test_a_down_robot_says_why_its_publisher_left_or_it_went_silent(page: Page, fleet: Exporter) -> None:
    open_page(page, fleet.url + "/")
    gone = page.locator('#groups tr[data-robot="gone/r1"]')
    expect(gone).to_have_attribute("data-down-reason", "publisher_left")
    expect(gone.locator("td").last).to_have_text(
        re.compile(r"^down: publisher left, last message \d+ s ago$")
    )
    quiet = page.locator('#groups tr[data-robot="quiet/r1"]')
    expect(quiet).to_have_attribute("data-down-reason", "silent")
    expect(quiet.locator("td").last).to_have_text(re.compile(r"^down: silent for \d+ s$"))
    open_page(page, fleet.url + "/?robot=quiet%2Fr1", view="robot")
    expect(page.locator("#robot-facts")).to_have_text(
        re.compile(r"^down: silent for \d+ s · dds · last message .+ \(\d+ s ago\) · 1 components")
    )
