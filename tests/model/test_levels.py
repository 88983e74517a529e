"""Severity order: ERROR > WARN > STALE > OK, as Nagios ranks CRITICAL > WARNING > UNKNOWN > OK."""

from __future__ import annotations

import pytest

from overseer.levels import Level, worst


@pytest.mark.parametrize(
    ("levels", "expected"),
    [
        ([], Level.OK),
        ([Level.OK, Level.OK], Level.OK),
        ([Level.OK, Level.STALE], Level.STALE),
        ([Level.STALE, Level.WARN], Level.WARN),
        ([Level.WARN, Level.STALE, Level.OK], Level.WARN),
        ([Level.STALE, Level.ERROR, Level.WARN], Level.ERROR),
        ([Level.ERROR, Level.STALE], Level.ERROR),
    ],
)
def test_worst_follows_severity_not_numeric_order(levels: list[Level], expected: Level) -> None:
    assert worst(levels) is expected


def test_levels_match_nagios_exit_codes() -> None:
    assert [int(level) for level in (Level.OK, Level.WARN, Level.ERROR, Level.STALE)] == [0, 1, 2, 3]
