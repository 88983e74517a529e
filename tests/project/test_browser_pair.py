"""The pinned Playwright drives the Chromium Debian ships: a pair that stops working says which pair.

Debian's chromium moves with security updates, the Playwright pin with the lock; when they part, this test
fails first, with "playwright X (made for chromium B) cannot drive chromium Y: ...", and CONTRIBUTING.md's
Playwright and Chromium section says what to do.
"""

from __future__ import annotations

import pytest
from playwright.sync_api import Error as PlaywrightError

from testbed.browser import bundled_chromium_version, cannot_drive, chromium_version, headless_chromium

pytestmark = pytest.mark.servers

PAGE = """<!doctype html><title>pair</title><ul id="robots"></ul>
<script>
  for (const name of ["robot1", "robot2"]) {
    const item = document.createElement("li");
    item.textContent = name;
    document.getElementById("robots").append(item);
  }
</script>"""


def test_the_versions_can_be_read() -> None:
    assert int(chromium_version().split(".")[0]) >= 100
    assert int(bundled_chromium_version().split(".")[0]) >= 100


def test_playwright_drives_debians_chromium_through_a_page_and_its_scripts() -> None:
    with headless_chromium() as browser:
        try:
            assert browser.version.split(".")[0] == chromium_version().split(".")[0]
            page = browser.new_page()
            page.set_content(PAGE)
            names = page.locator("#robots li").all_inner_texts()
            total = page.evaluate("() => [...document.querySelectorAll('li')].length + 40")
            page.close()
        except PlaywrightError as error:
            pytest.fail(cannot_drive(error))
    assert names == ["robot1", "robot2"]
    assert total == 42
