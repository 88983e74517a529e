"""The workers' launcher: a fresh interpreter gets its function, its pipes and its counts, nothing else."""

from __future__ import annotations

import os
import signal
import sys
import time
from multiprocessing.connection import Connection, Pipe

import pytest

from overseer.fleet.workers.launch import start_child
from overseer.fleet.workers.shared_counts import SharedCounts

TIMEOUT_SECONDS = 30.0


def answer_and_count(requests: Connection, results: Connection, counts: SharedCounts, slot: int) -> None:
    """In the child: answer one request on a two-way pipe, write a one-way one, and count in a slot."""
    question = requests.recv()
    requests.send(("answer", question, os.getpid()))
    results.send_bytes(b"x" * 100_000)  # more than a pipe's buffer: the parent reads while it is written
    counts.slots[slot] = os.getpid()
    counts.slots[0] += 1


def wait_then_raise(start: Connection) -> None:
    """In the child: wait for a word from the parent, then fail."""
    start.recv()
    raise ValueError("a worker that cannot start")


def wait_forever(start: Connection) -> None:
    """In the child: say it runs, then wait until killed."""
    start.send(os.getpid())
    signal.pause()


def test_a_child_uses_the_pipes_and_counts_it_was_given() -> None:
    requests, child_requests = Pipe()
    results, child_results = Pipe(duplex=False)
    counts = SharedCounts.create(3)
    counts.slots[0] = 41
    child = start_child(answer_and_count, (child_requests, child_results, counts, 2))
    child_requests.close()
    child_results.close()
    try:
        requests.send("question")
        assert requests.poll(TIMEOUT_SECONDS), "the child never answered"
        assert requests.recv() == ("answer", "question", child.pid)
        assert results.recv_bytes() == b"x" * 100_000
        child.join(TIMEOUT_SECONDS)
        assert child.exitcode == 0
        assert counts.slots.tolist() == [42, 0, child.pid]  # what it wrote is in the parent's memory
        with pytest.raises(EOFError):
            requests.recv()  # the child's end left with it: no other process held it open
    finally:
        child.kill()


def test_a_child_whose_function_raises_exits_with_1_and_says_why(capfd: pytest.CaptureFixture[str]) -> None:
    start, child_start = Pipe()
    child = start_child(wait_then_raise, (child_start,))
    child_start.close()
    try:
        assert child.is_alive()
        start.send("go")
        child.join(TIMEOUT_SECONDS)
        assert child.exitcode == 1
        assert not child.is_alive()
    finally:
        child.kill()
    assert "ValueError: a worker that cannot start" in capfd.readouterr().err


def test_a_killed_child_tells_the_signal_and_join_waits_no_longer_than_asked() -> None:
    start, child_start = Pipe()
    child = start_child(wait_forever, (child_start,))
    child_start.close()
    try:
        assert start.poll(TIMEOUT_SECONDS) and start.recv() == child.pid
        began = time.monotonic()
        child.join(0.2)
        assert child.is_alive() and child.exitcode is None
        assert time.monotonic() - began < TIMEOUT_SECONDS / 2
        child.kill()
        child.join(TIMEOUT_SECONDS)
        assert child.exitcode == -signal.SIGKILL
        child.kill()  # an ended child: nothing to do, and no error
    finally:
        child.kill()


def test_a_child_that_ends_before_reading_its_arguments_leaves_its_exit_code_and_its_pipes_closed(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.setattr(sys, "executable", "/bin/false")  # an interpreter that fails at once
    requests, child_requests = Pipe()
    child = start_child(wait_then_raise, (child_requests, b"x" * 4_000_000))  # beyond the pipe: a broken one
    child_requests.close()
    child.join(TIMEOUT_SECONDS)
    assert child.exitcode == 1
    assert requests.poll(TIMEOUT_SECONDS)
    with pytest.raises(EOFError):
        requests.recv()


def test_closed_counts_let_go_of_their_descriptor_and_stay_readable() -> None:
    counts = SharedCounts.create(2)
    counts.slots[1] = 7
    descriptor = counts.fileno()
    os.fstat(descriptor)
    counts.close()
    with pytest.raises(OSError):
        os.fstat(descriptor)
    assert counts.slots.tolist() == [0, 7]  # mapped on a descriptor of the mapping's own
    counts.close()  # twice: nothing more to do
