"""A clock a test moves by hand, for the parts that take their notion of time as a callable."""

from __future__ import annotations

FIXED_UNIX_TIME = 1_700_000_000.0


class ManualClock:
    """Answers `now`, which the test sets or moves on; nothing else moves it."""

    def __init__(self, start: float = FIXED_UNIX_TIME) -> None:
        """Start at `start` (by default a fixed unix time, so that what is rendered is reproducible)."""
        self.now = start

    def __call__(self) -> float:
        """The current time."""
        return self.now
