"""Debian's Chromium, headless, driven through Playwright: the status page in a real browser."""

from __future__ import annotations

import shutil
import time
from collections.abc import Iterator
from contextlib import contextmanager

from playwright.sync_api import Browser, Page, sync_playwright

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


@contextmanager
def headless_chromium() -> Iterator[Browser]:
    """A headless Chromium for the block, closed after it."""
    with sync_playwright() as playwright:
        browser = playwright.chromium.launch(executable_path=chromium_path(), args=CHROMIUM_ARGS)
        try:
            yield browser
        finally:
            browser.close()


class PageErrors:
    """Uncaught exceptions of a page's scripts, collected so a test can assert there were none."""

    def __init__(self, page: Page) -> None:
        """Start collecting `page`'s errors."""
        self.errors: list[str] = []
        page.on("pageerror", lambda error: self.errors.append(str(error)))


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
