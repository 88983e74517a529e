"""A thread lowers its own scheduling priority by some nice levels; the other threads keep theirs."""

from __future__ import annotations

import os
import threading

from overseer.thread_priority import LOWEST_PRIORITY, lower_thread_priority


def niceness_in_a_thread_lowered_by(steps: int) -> int:
    """The nice value of a new thread once it has lowered itself by `steps`."""
    seen: list[int] = []

    def lowered() -> None:
        lower_thread_priority(steps)
        seen.append(os.getpriority(os.PRIO_PROCESS, threading.get_native_id()))

    thread = threading.Thread(target=lowered)
    thread.start()
    thread.join()
    return seen[0]


def test_a_thread_lowers_itself_by_the_steps_asked_and_the_process_stays_as_it_was() -> None:
    own = os.getpriority(os.PRIO_PROCESS, threading.get_native_id())
    assert own + 3 <= LOWEST_PRIORITY  # the test's own process is not at the lowest already
    assert niceness_in_a_thread_lowered_by(3) == own + 3
    assert os.getpriority(os.PRIO_PROCESS, threading.get_native_id()) == own
    assert os.getpriority(os.PRIO_PROCESS, 0) == own


def test_lowering_stops_at_the_lowest_priority_and_zero_steps_change_nothing() -> None:
    own = os.getpriority(os.PRIO_PROCESS, threading.get_native_id())
    assert niceness_in_a_thread_lowered_by(LOWEST_PRIORITY + 10) == LOWEST_PRIORITY
    assert niceness_in_a_thread_lowered_by(0) == own
