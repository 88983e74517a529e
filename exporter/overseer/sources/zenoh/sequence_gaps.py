"""Samples a publisher sent that never arrived, from the sequence numbers rmw_zenoh attaches to them.

rmw_zenoh numbers each publisher's samples one by one (a publisher that starts again has a new GID). A
jump from n to n + k means k - 1 samples were published and not heard: dropped by a congested router or
link, or by a subscriber that could not keep up. A number that does not move forward (a repeat, a late
or stray sample) is ignored and counting goes on from the highest heard; a jump of more than a million,
which no diagnostics publisher loses while it stays alive (at 10 Hz, 28 hours), is a numbering gone
wrong and is not counted. These bound what one wild number adds; a publisher that forges a robot's
attachments can forge its diagnostics too, so they are no defence against it.
"""

from __future__ import annotations

MAX_GAP = 1_000_000  # samples between two heard that can be counted lost


class SequenceGaps:
    """The highest sequence number heard from each publisher, and how many were missed before it."""

    def __init__(self) -> None:
        """Start with no publisher heard."""
        self._last: dict[bytes, int] = {}
        self._lost: dict[bytes, int] = {}

    def missed(self, gid: bytes, sequence: int) -> int:
        """How many samples of publisher `gid` were published between the highest heard and `sequence`."""
        last = self._last.get(gid)
        if last is not None and sequence <= last:
            return 0  # a repeat or a late sample: not a loss, and not where counting goes on from
        self._last[gid] = sequence
        if last is None or sequence > last + MAX_GAP + 1:
            return 0  # the first heard, or numbers that cannot be trusted
        missed = sequence - last - 1
        if missed:
            self._lost[gid] = self._lost.get(gid, 0) + missed
        return missed

    def heard(self, gid: bytes, sequence: int) -> None:
        """Take `sequence` as heard though it was not kept (dropped, and counted as such, by a full queue)."""
        last = self._last.get(gid)
        if last is not None and last < sequence <= last + MAX_GAP + 1:
            self._last[gid] = sequence

    def lost(self, gid: bytes) -> int:
        """All the samples of publisher `gid` counted missed so far."""
        return self._lost.get(gid, 0)

    def forget(self, gid: bytes) -> None:
        """Drop what is known of publisher `gid` (its robot was forgotten)."""
        self._last.pop(gid, None)
        self._lost.pop(gid, None)
