"""Runs of robots' deflated pieces compressed again as one piece once they stop changing.

Every robot's lines of a family are a piece of their own (`deflated`), so that a scrape copies the bytes
of a robot that did not change. Laid end to end, ten thousand small pieces are a larger answer than one
stream: each piece starts with no history to refer to, and ends its blocks with a flush (at 10,000
robots, levels and messages only, 5.7 MB where gzip makes 3.9 MB of the same text, for the scraper to
read and unzip at every scrape). Yet in a fleet most robots' levels and messages stay the same for
minutes: a run of consecutive robots whose pieces are those of the render before is inflated and
deflated again as one piece (about 20 ms of CPU for a thousand robots' levels and messages), which
later renders send as long as none of them changes. A run that changed is sent as its pieces until it
holds still again for a render, so that a family that changes at every render (live values) is never
compressed twice.

Runs end where a robot's name hashes to a multiple of `RUN_ROBOTS` (at the latest after
`MOST_RUN_ROBOTS` robots): a robot that comes or goes changes the run it falls in (the two it joins or
splits, when its name ends a run), not every run after it (but in a streak of names of which none ends
a run, which are cut by count).
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from dataclasses import dataclass

from overseer.fleet.deflated import Deflated, deflate, inflate, join

RUN_ROBOTS = 32  # robots a run on average: a block of zlib's own at the length of a robot's levels
MOST_RUN_ROBOTS = 4 * RUN_ROBOTS


@dataclass(slots=True)
class _Run:
    """A run's pieces as last rendered, and the same text as one piece once it held still for a render."""

    pieces: tuple[Deflated, ...]
    joined: Deflated | None = None


class JoinedRuns:
    """A family's robots' pieces joined into one, runs that held still for a render recompressed whole.

    Not safe to share between threads: the exposition joins under its own lock.
    """

    def __init__(self) -> None:
        """Know of no run yet: the first render sends every piece as it is."""
        self._runs: dict[str, _Run] = {}
        self.recompressed = 0  # runs compressed again as one piece, since the start (the tests read it)

    def join(self, names: Sequence[str], pieces: Sequence[Deflated]) -> Deflated:
        """The pieces in order as one piece; `names[i]` is the robot of `pieces[i]`."""
        before, runs = self._runs, {}
        laid: list[Deflated] = []
        for start, stop in _run_bounds(names):
            run = tuple(pieces[start:stop])
            kept = before.get(names[start])
            # The same objects but for a robot rendered again to the same bytes: compared by identity first.
            if kept is None or kept.pieces != run:
                runs[names[start]] = _Run(run)
                laid += run
                continue
            if kept.joined is None:
                kept.joined = deflate(b"".join(map(inflate, run)))
                self.recompressed += 1
            kept.pieces = run  # the pieces now: an equal one rendered anew frees the old
            runs[names[start]] = kept
            laid.append(kept.joined)
        self._runs = runs
        return join(laid)


def _run_bounds(names: Sequence[str]) -> Iterator[tuple[int, int]]:
    """Where each run of robots starts and stops, decided by the robots' names."""
    start = 0
    for index, name in enumerate(names):
        if hash(name) % RUN_ROBOTS == 0 or index + 1 - start == MOST_RUN_ROBOTS:
            yield start, index + 1
            start = index + 1
    if start < len(names):
        yield start, len(names)
