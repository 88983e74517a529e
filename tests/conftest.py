"""Fixtures shared by the whole suite."""

from __future__ import annotations

from collections.abc import Iterator
from typing import TYPE_CHECKING

import pytest

from testbed.paths import REPO
from testbed.ports import fresh_domain_id

if TYPE_CHECKING:
    from playwright.sync_api import Browser


@pytest.fixture
def dds_domain() -> int:
    """A DDS domain id of this test's own, so concurrent tests never hear each other."""
    return fresh_domain_id()


@pytest.fixture(autouse=True)
def repository_left_clean(request: pytest.FixtureRequest) -> Iterator[None]:
    """No test leaves an event database in the repository (a configuration error must open nothing)."""
    stray = REPO / "overseer-events.db"
    existed = stray.exists()
    yield
    assert existed or not stray.exists(), f"{request.node.nodeid} made {stray}"


@pytest.fixture(scope="module")
def browser() -> Iterator[Browser]:
    """One headless Chromium for the module (Playwright is imported only by the tests that use it)."""
    from testbed.browser import headless_chromium

    with headless_chromium() as browser:
        yield browser
