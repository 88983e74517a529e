"""A wall clock that never steps: unix time as read at start, carried on by the monotonic clock.

Every age the exporter judges (a component's staleness, a robot's silence, expiry) is measured on the
monotonic clock. Judgements against absolute times (a maintenance window ends at 14:00) use this clock:
it reads like the wall clock, but a step of the system clock (an NTP step, a VM resumed) does not move it,
so it ends no window early and starts none twice. After a step it differs from the system clock by the
step until the exporter restarts.
"""

from __future__ import annotations

import time
from collections.abc import Callable


class SteadyWallClock:
    """Unix time that advances with the monotonic clock from the moment it was made."""

    def __init__(
        self, wall: Callable[[], float] = time.time, monotonic: Callable[[], float] = time.monotonic
    ) -> None:
        """Read `wall` once, and follow `monotonic` from then on."""
        self._monotonic = monotonic
        self._offset = wall() - monotonic()

    def __call__(self) -> float:
        """Unix time now, as the wall clock read at start and the monotonic clock since say."""
        return self._monotonic() + self._offset


steady_time = SteadyWallClock()
