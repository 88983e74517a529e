"""Debian's Chromium, headless, driven through Playwright: the status page in a real browser.

Playwright talks to Chromium over the DevTools protocol as its driver knows it, the protocol of the Chromium
build it bundles (its browsers.json). Debian's Chromium follows Chrome's stable releases with security
updates, a few majors from the pinned Playwright's; a pair that stops working fails at launch or at the
first page, and every failure here names both versions.
"""

from __future__ import annotations

import json
import re
import shutil
import subprocess
import time
from collections.abc import Iterator
from contextlib import contextmanager
from importlib import metadata
from pathlib import Path
from typing import Any

import playwright
from playwright.sync_api import Browser, ConsoleMessage, Page, sync_playwright
from playwright.sync_api import Error as PlaywrightError

CHROMIUM_ARGS = [
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
]


def chromium_path() -> str:
    """The system Chromium (Debian package chromium): Playwright never downloads a browser here."""
    path = shutil.which("chromium") or shutil.which("chromium-browser")
    assert path, "chromium is installed by scripts/install-system-deps test (Debian package chromium)"
    return path


def chromium_version() -> str:
    """The system Chromium's version, as `chromium --version` prints it (156.0.8078.79)."""
    output = subprocess.run([chromium_path(), "--version"], capture_output=True, text=True, timeout=60).stdout
    match = re.search(r"\b(\d+\.\d+\.\d+\.\d+)\b", output)
    assert match, f"{chromium_path()} --version printed {output!r}"
    return match[1]


def bundled_chromium_version() -> str:
    """The Chromium build the installed Playwright's driver is made for (never downloaded here)."""
    browsers = Path(playwright.__file__).parent / "driver" / "package" / "browsers.json"
    entries = json.loads(browsers.read_text(encoding="utf-8"))["browsers"]
    return str(next(entry["browserVersion"] for entry in entries if entry["name"] == "chromium"))


def cannot_drive(error: Exception) -> str:
    """What a failure of the pair says: "playwright X (made for chromium B) cannot drive chromium Y: ..."."""
    bundled, system = bundled_chromium_version(), chromium_version()
    apart = int(bundled.split(".")[0]) - int(system.split(".")[0])
    distance = f"{abs(apart)} majors {'older' if apart > 0 else 'newer'}" if apart else "the same major"
    return (
        f"playwright {metadata.version('playwright')} (made for chromium {bundled}) cannot drive chromium "
        f"{system} ({distance}): {error}. Pin a Playwright made for a Chromium nearer Debian's "
        "(CONTRIBUTING.md, Playwright and Chromium)"
    )


@contextmanager
def headless_chromium() -> Iterator[Browser]:
    """A headless Chromium for the block, closed after it; a failed launch names both versions."""
    with sync_playwright() as driver:
        try:
            browser = driver.chromium.launch(executable_path=chromium_path(), args=CHROMIUM_ARGS)
        except PlaywrightError as error:
            raise AssertionError(cannot_drive(error)) from error
        try:
            yield browser
        finally:
            browser.close()


class PageErrors:
    """Uncaught exceptions of a page's scripts and errors on its console, for a test to assert none.

    Console errors are what a browser says of a file it could not load (a 404) or a refused script.
    """

    def __init__(self, page: Page) -> None:
        """Start collecting `page`'s errors."""
        self.errors: list[str] = []
        self.expected_failures: list[str] = []  # URLs a test makes fail on purpose
        page.on("pageerror", lambda error: self.errors.append(str(error)))
        page.on("console", self._on_console)
        _collectors[id(page)] = self

    def _on_console(self, message: ConsoleMessage) -> None:
        if message.type != "error":
            return
        url = str(message.location.get("url", ""))
        if message.text.startswith("Failed to load resource") and any(
            part in url for part in self.expected_failures
        ):
            return  # the test made this request fail, and checks that the page says so
        self.errors.append(f"console: {message.text} ({url})")


_collectors: dict[int, PageErrors] = {}


def expect_failed_request(page: Page, url_part: str) -> None:
    """Let requests whose URL holds `url_part` fail without failing the page: the test makes them fail."""
    _collectors[id(page)].expected_failures.append(url_part)


@contextmanager
def error_free_page(browser: Browser, **context_options: Any) -> Iterator[Page]:
    """A page in its own browser context for the block (1280x900 unless told); fails on any script error."""
    context = browser.new_context(**{"viewport": {"width": 1280, "height": 900}, **context_options})
    page = context.new_page()
    errors = PageErrors(page)
    try:
        yield page
    finally:
        context.close()
        _collectors.pop(id(page), None)
    assert errors.errors == [], errors.errors


def open_page(page: Page, url: str, view: str = "fleet") -> None:
    """Go to `url` and wait until the status page shows `view` (fleet or robot)."""
    page.goto(url)
    page.wait_for_selector(f"body[data-view={view}]")


def refreshes(page: Page) -> int:
    """How many times the page has rendered fresh data from the exporter."""
    return int(page.evaluate("Number(document.body.dataset.refreshes || 0)"))


def wait_for_refresh(page: Page, timeout: float = 15.0) -> None:
    """Wait until the page has refreshed itself (auto-refresh) at least once more from now.

    Polled from here: the page's Content-Security-Policy forbids the eval that wait_for_function needs.
    """
    count = refreshes(page)
    deadline = time.monotonic() + timeout
    while refreshes(page) <= count:
        assert time.monotonic() < deadline, f"the page did not refresh within {timeout}s"
        page.wait_for_timeout(100)
