"""Samples a publisher sent that never arrived, from the sequence numbers rmw_zenoh attaches to them.

rmw_zenoh numbers each publisher's samples one by one. A jump from n to n + k means k - 1 samples were
published and not heard: dropped by a congested router or link, or by a subscriber that could not keep
up. A number that does not move forward is a publisher that started over (or a repeat), not a loss; nor
is a jump of more than a million, which no diagnostics publisher loses while it stays alive (at 10 Hz,
28 hours): a numbering gone wrong, or a forged one, does not inflate the count.
"""

from __future__ import annotations

from collections.abc import Hashable

MAX_GAP = 1_000_000  # samples between two heard that can be counted lost


class SequenceGaps:
    """The last sequence number heard from each feed, and how many a new one says were missed."""

    def __init__(self) -> None:
        """Start with no feed heard."""
        self._last: dict[Hashable, int] = {}

    def missed(self, feed: Hashable, sequence: int) -> int:
        """How many samples of `feed` were published between its last one heard and `sequence`."""
        last = self._last.get(feed)
        self._last[feed] = sequence
        if last is None or not last < sequence <= last + MAX_GAP + 1:
            return 0  # the first heard, the publisher started over, or numbers that cannot be trusted
        return sequence - last - 1

    def forget(self, feed: Hashable) -> None:
        """Drop what is known of `feed` (its robot was forgotten)."""
        self._last.pop(feed, None)
