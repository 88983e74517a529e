"""What a publisher sent and was never heard, from the sequence numbers of the samples that were."""

from __future__ import annotations

from overseer.sources.zenoh.sequence_gaps import MAX_GAP, SequenceGaps


def test_numbers_one_apart_miss_nothing_and_a_jump_misses_those_between() -> None:
    gaps = SequenceGaps()
    assert [gaps.missed("feed", number) for number in (5, 6, 7)] == [0, 0, 0]
    assert gaps.missed("feed", 11) == 3
    assert gaps.missed("feed", 12) == 0


def test_a_publisher_that_starts_over_or_repeats_misses_nothing() -> None:
    gaps = SequenceGaps()
    gaps.missed("feed", 900)
    assert gaps.missed("feed", 900) == 0  # a repeat
    assert gaps.missed("feed", 1) == 0  # started over: counted from there
    assert gaps.missed("feed", 3) == 1


def test_feeds_are_counted_apart_and_a_forgotten_one_starts_afresh() -> None:
    gaps = SequenceGaps()
    gaps.missed("a", 1)
    gaps.missed("b", 100)
    assert gaps.missed("a", 2) == 0
    assert gaps.missed("b", 102) == 1
    gaps.forget("b")
    gaps.forget("never heard")
    assert gaps.missed("b", 500) == 0  # heard again after its robot was forgotten: no gap to measure


def test_a_jump_too_large_to_be_losses_is_not_counted_and_numbering_goes_on_from_it() -> None:
    gaps = SequenceGaps()
    gaps.missed("feed", 10)
    assert gaps.missed("feed", 11 + MAX_GAP) == MAX_GAP  # the largest gap counted
    assert gaps.missed("feed", 2**62) == 0  # forged, or a numbering gone wrong
    assert gaps.missed("feed", 2**62 + 2) == 1
