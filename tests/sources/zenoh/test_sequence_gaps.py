"""What a publisher sent and was never heard, from the sequence numbers of the samples that were."""

from __future__ import annotations

from overseer.sources.zenoh.sequence_gaps import MAX_GAP, SequenceGaps

A, B = b"\x01" * 16, b"\x02" * 16  # two publishers' GIDs


def test_numbers_one_apart_miss_nothing_and_a_jump_misses_those_between() -> None:
    gaps = SequenceGaps()
    assert [gaps.missed(A, number) for number in (5, 6, 7)] == [0, 0, 0]
    assert gaps.missed(A, 11) == 3
    assert gaps.missed(A, 12) == 0
    assert gaps.lost(A) == 3


def test_a_repeat_or_a_late_sample_misses_nothing_and_counting_goes_on_from_the_highest() -> None:
    gaps = SequenceGaps()
    assert [gaps.missed(A, number) for number in (10, 11, 12, 12, 8, 13)] == [0] * 6
    assert gaps.missed(A, 1) == 0  # a stray number, however low, does not move the count back
    assert gaps.missed(A, 14) == 0
    assert gaps.missed(A, 16) == 1
    assert gaps.lost(A) == 1


def test_publishers_are_counted_apart_and_a_forgotten_one_starts_afresh() -> None:
    gaps = SequenceGaps()
    gaps.missed(A, 1)
    gaps.missed(B, 100)
    assert gaps.missed(A, 2) == 0
    assert gaps.missed(B, 102) == 1
    gaps.forget(B)
    gaps.forget(b"never heard")
    assert gaps.lost(B) == 0
    assert gaps.missed(B, 500) == 0  # heard again after its robot was forgotten: no gap to measure


def test_a_jump_too_large_to_be_losses_is_not_counted_and_numbering_goes_on_from_it() -> None:
    gaps = SequenceGaps()
    gaps.missed(A, 10)
    assert gaps.missed(A, 11 + MAX_GAP) == MAX_GAP  # the largest gap counted
    assert gaps.missed(A, 11 + MAX_GAP + MAX_GAP + 2) == 0  # the smallest that is not
    assert gaps.missed(A, 2**62) == 0  # a numbering gone wrong
    assert gaps.missed(A, 2**62 + 2) == 1
    assert gaps.lost(A) == MAX_GAP + 1


def test_a_number_dropped_by_a_full_queue_is_heard_and_not_counted_lost_as_well() -> None:
    gaps = SequenceGaps()
    gaps.missed(A, 1)
    gaps.heard(A, 2)  # dropped, and counted dropped, by the worker's full queue
    gaps.heard(B, 7)  # a publisher not heard yet: nothing to go on from
    assert gaps.missed(A, 3) == 0
    assert gaps.missed(B, 9) == 0
    assert gaps.lost(A) == gaps.lost(B) == 0
