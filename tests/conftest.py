"""Fixtures shared by the whole suite."""

from __future__ import annotations

import pytest

from testbed.ports import fresh_domain_id


@pytest.fixture
def dds_domain() -> int:
    """A DDS domain id of this test's own, so concurrent tests never hear each other."""
    return fresh_domain_id()
