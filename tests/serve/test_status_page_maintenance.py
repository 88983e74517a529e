"""Maintenance on the status page, in a real headless Chromium (Debian's, through Playwright).

Each test runs an exporter in the test process with basic auth (alice may write windows, bob may only
read), its robots fed by the test: robot1 OK, site_a/r1 and site_a/r2 in ERROR, site_a/r3 silent (down).
The browser logs in as one of them with HTTP basic auth, as a user's browser does.
"""

from __future__ import annotations

import json
from base64 import b64encode
from collections.abc import Iterator
from pathlib import Path

import bcrypt
import pytest
from playwright.sync_api import Browser, Page, expect

from overseer.app import Exporter
from testbed.browser import error_free_page, expect_failed_request, open_page
from testbed.in_process import call, in_process_exporter, publish

pytestmark = pytest.mark.servers

HASH = bcrypt.hashpw(b"secret", bcrypt.gensalt(rounds=4)).decode()
HOSTILE_COMMENT = '<img src=x onerror=window.pwned=1> swap & "fix"'


@pytest.fixture
def running(tmp_path: Path) -> Iterator[Exporter]:
    """The exporter, its robots published, robot site_a/r3 down (marked so by its transport)."""
    web_config = tmp_path / "web.yml"
    web_config.write_text(f"basic_auth_users:\n  alice: '{HASH}'\n  bob: '{HASH}'\n", encoding="utf-8")
    with in_process_exporter(
        tmp_path,
        web={"config_file": str(web_config), "enable_maintenance_api": True},
        maintenance={"writers": ["alice"]},
    ) as exporter:
        publish(exporter, "robot1", (0, "/Power", "ok"))
        for robot in ("site_a/r1", "site_a/r2", "site_a/r3"):
            publish(exporter, robot, (2, "/Laser", "no scans"), (0, "/Power", "ok"))
        assert exporter.model is not None
        exporter.model.publisher_left("site_a/r3")
        yield exporter


def page_as(browser: Browser, user: str) -> Iterator[Page]:
    with error_free_page(browser, http_credentials={"username": user, "password": "secret"}) as page:
        yield page


@pytest.fixture
def alice(browser: Browser) -> Iterator[Page]:
    """A page logged in as alice, who may write windows."""
    yield from page_as(browser, "alice")


@pytest.fixture
def bob(browser: Browser) -> Iterator[Page]:
    """A page logged in as bob, who may only read them."""
    yield from page_as(browser, "bob")


def test_a_writer_starts_a_window_from_the_page_and_its_robots_are_shown_in_maintenance_not_red(
    alice: Page, running: Exporter
) -> None:
    open_page(alice, running.server.url + "/")
    expect(alice.locator('#groups tr[data-robot="site_a/r1"]')).to_have_attribute("data-state", "ERROR")
    expect(alice.locator('details[data-group="site_a"] > summary .badge')).to_have_text("ERROR")
    alice.fill("#maintenance-robots", "site_a/")
    alice.select_option("#maintenance-duration", "4h")
    alice.fill("#maintenance-comment", HOSTILE_COMMENT)
    alice.click("#maintenance-form button[type=submit]")

    row = alice.locator("#maintenance-rows tr")
    expect(row).to_have_count(1)
    expect(row.locator("td").nth(5)).to_have_text(HOSTILE_COMMENT)
    expect(row.locator("td").nth(4)).to_have_text("alice")
    for robot in ("site_a/r1", "site_a/r2", "site_a/r3"):
        robot_row = alice.locator(f'#groups tr[data-robot="{robot}"]')
        expect(robot_row).to_have_attribute("data-state", "MAINTENANCE")
        expect(robot_row).to_have_class("maintenance")
        expect(robot_row.locator(".badge")).to_have_text("MAINTENANCE")
        expect(robot_row.locator(".maintenance-note")).to_contain_text(f"alice: {HOSTILE_COMMENT}")
    expect(alice.locator('details[data-group="site_a"] > summary .badge')).to_have_text("MAINTENANCE")
    expect(alice.locator('[data-total="maintenance"]')).to_have_text("in maintenance 3")
    expect(alice.locator('[data-total="down"]')).to_have_text("down 0")
    expect(alice.locator('[data-total="ERROR"]')).to_have_text("0")
    assert alice.evaluate("window.pwned") is None
    _, listing = call(running, "/api/v1/maintenance", headers=_basic("alice"))
    [window] = listing["windows"]
    assert (window["robots"], window["comment"], window["author"]) == ("site_a/", HOSTILE_COMMENT, "alice")
    assert window["end"] - window["start"] == pytest.approx(4 * 3600, abs=2)


def test_a_writer_ends_a_robots_window_from_its_view_and_it_turns_red_again(
    alice: Page, running: Exporter
) -> None:
    status, _ = call(
        running,
        "/api/v1/maintenance",
        "POST",
        json.dumps({"robots": "site_a/r1", "duration": "1h", "comment": "laser swap"}).encode(),
        {**_basic("alice"), "Content-Type": "application/json"},
    )
    assert status == 201
    open_page(alice, running.server.url + "/?robot=site_a/r1", view="robot")
    expect(alice.locator("#robot-title .badge")).to_have_text("MAINTENANCE")
    expect(alice.locator("#robot-maintenance-state")).to_contain_text("in maintenance until")
    expect(alice.locator("#robot-maintenance-state")).to_contain_text("alice: laser swap")
    expect(alice.locator("#robot-maintenance-form")).to_be_hidden()
    alice.click("#robot-maintenance-end button")
    expect(alice.locator("#robot-title .badge")).to_have_text("ERROR")
    expect(alice.locator("#robot-maintenance-state")).to_have_text("")
    expect(alice.locator("#robot-maintenance-form")).to_be_visible()
    expect(alice.locator('#timeline-events li[data-kind="maintenance_end"]')).to_have_count(1)

    alice.select_option("#robot-maintenance-duration", "30m")
    alice.fill("#robot-maintenance-comment", "recalibration")
    alice.click("#robot-maintenance-form button[type=submit]")
    expect(alice.locator("#robot-title .badge")).to_have_text("MAINTENANCE")
    expect(alice.locator("#robot-maintenance-state")).to_contain_text("alice: recalibration")


def test_the_exporters_refusal_is_shown_where_the_user_typed(alice: Page, running: Exporter) -> None:
    expect_failed_request(alice, "/api/v1/maintenance")  # the exporter refuses the window: a 400
    open_page(alice, running.server.url + "/")
    alice.fill("#maintenance-robots", "site_a/r1; DROP TABLE")
    alice.fill("#maintenance-comment", "why not")
    alice.click("#maintenance-form button[type=submit]")
    expect(alice.locator("#maintenance-error")).to_contain_text("robots: expected a robot name")
    expect(alice.locator("#maintenance-robots")).to_have_value("site_a/r1; DROP TABLE")  # kept, to correct
    expect(alice.locator("#maintenance-rows tr")).to_have_count(0)


def test_a_reader_sees_the_windows_but_no_controls(bob: Page, running: Exporter) -> None:
    status, _ = call(
        running,
        "/api/v1/maintenance",
        "POST",
        json.dumps({"robots": "robot1", "duration": "1h", "comment": "parked"}).encode(),
        {**_basic("alice"), "Content-Type": "application/json"},
    )
    assert status == 201
    open_page(bob, running.server.url + "/")
    expect(bob.locator("#maintenance-rows tr")).to_have_count(1)
    expect(bob.locator("#maintenance-rows button")).to_have_count(0)
    expect(bob.locator("#maintenance-form")).to_be_hidden()
    expect(bob.locator('#groups tr[data-robot="robot1"] .badge')).to_have_text("MAINTENANCE")
    open_page(bob, running.server.url + "/?robot=robot1", view="robot")
    expect(bob.locator("#robot-maintenance-state")).to_contain_text("alice: parked")
    expect(bob.locator("#robot-maintenance-end button")).to_have_count(0)
    expect(bob.locator("#robot-maintenance-form")).to_be_hidden()


def _basic(user: str) -> dict[str, str]:
    return {"Authorization": "Basic " + b64encode(f"{user}:secret".encode()).decode()}
