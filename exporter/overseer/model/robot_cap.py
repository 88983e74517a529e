"""How many robots a fleet model may take: `fleet.max_robots`, in one model or across the ingest workers'.

The workers split a fleet by a hash of the robots' names, which is never exactly even. A share of the cap
each would refuse robots while the fleet is under it (three robots hashed to one of two workers, with a
cap of three, left one of them out), so the workers count their robots in shared memory instead, and a
robot is refused once the whole fleet holds the cap.
"""

from __future__ import annotations

from collections.abc import Iterator
from typing import Protocol

ATTEMPTS = 3  # a worker that met another taking the last places at the same moment looks again


class Counts(Protocol):
    """One count a model, each written by its own model and read by all (the workers' `SharedCounts`)."""

    def __getitem__(self, index: int, /) -> int: ...

    def __setitem__(self, index: int, value: int, /) -> None: ...

    def __iter__(self) -> Iterator[int]: ...


class RobotCap:
    """`limit` robots, counted in one fleet model alone."""

    def __init__(self, limit: int) -> None:
        """Let a model hold up to `limit` robots."""
        self.limit = limit

    def admit(self, held: int) -> bool:
        """Whether a model that holds `held` robots may take one more; counted at once if so."""
        return held < self.limit

    def holds(self, held: int) -> None:
        """The model now holds `held` robots (after it forgot some, or took listed ones past the cap)."""


class SharedRobotCap(RobotCap):
    """`limit` robots across several processes' models, each counting its own in its slot of `counts`.

    Each process writes only its own slot, and no lock is shared: a worker killed at any moment (the pool
    kills one that hangs) cannot leave the others waiting for good. A robot is counted before the fleet is
    added up again, so two workers taking the last place at the same moment see each other and do not
    both take it. Without a memory barrier between the write and the reads that holds in practice (the
    interpreter runs a great many instructions between them), not by proof: at worst the fleet goes past
    the cap by a robot a worker.
    """

    def __init__(self, limit: int, counts: Counts, slot: int) -> None:
        """Count this model's robots in `counts[slot]`, from none (a worker started again relearns them)."""
        super().__init__(limit)
        self._counts = counts
        self._slot = slot
        counts[slot] = 0

    def admit(self, held: int) -> bool:
        """Whether the fleet, with this model's `held` and one more, stays within `limit`; counted if so."""
        counts, slot = self._counts, self._slot
        for _ in range(ATTEMPTS):
            if sum(counts) - counts[slot] + held >= self.limit:
                return False  # full: nothing written, so a refused robot's every message costs no write
            counts[slot] = held + 1
            if sum(counts) <= self.limit:
                return True
            counts[slot] = held  # another worker took the place meanwhile
        return False

    def holds(self, held: int) -> None:
        """Count `held` robots for this model."""
        self._counts[self._slot] = held
