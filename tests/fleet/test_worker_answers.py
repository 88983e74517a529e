"""A worker's answers cross the request pipe whole, in order, beside the requests going the other way."""

from __future__ import annotations

import os
import socket
import struct
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from multiprocessing.connection import Connection, Pipe

import pytest

from overseer.fleet.workers.answers import receive_answer, send_answer
from overseer.fleet.workers.launch import ChildProcess, start_child

TIMEOUT_SECONDS = 30.0
LARGE = 8 * 1024 * 1024  # a worker's exposition part at 5,000 robots: many times a socket's buffer


def answer_twice(requests: Connection) -> None:
    """In the child: answer each of two requests with a large answer, then a small one."""
    for _ in range(2):
        size = requests.recv()
        send_answer(requests, ("ok", bytes(range(256)) * (size // 256), os.getpid()))
    send_answer(requests, ("ok", None))


def answer_short(requests: Connection) -> None:
    """In the child: begin an answer of 1 MB, write half of it, and leave."""
    requests.recv()
    descriptor = requests.fileno()
    os.write(descriptor, struct.pack("!Q", 1 << 20))
    os.write(descriptor, b"x" * (1 << 19))


def answer_halfway_and_hang(requests: Connection) -> None:
    """In the child: begin an answer of 1 MB, write half of it, and stop there (the pipe left open)."""
    answer_short(requests)
    time.sleep(TIMEOUT_SECONDS)


@contextmanager
def worker(target: Callable[[Connection], None]) -> Iterator[tuple[Connection, ChildProcess]]:
    """`target` run in a child started as the pool starts its workers; the exporter's end of its pipe."""
    requests, child_requests = Pipe()
    child = start_child(target, (child_requests,))
    child_requests.close()
    try:
        yield requests, child
    finally:
        child.kill()
        requests.close()


def test_large_answers_arrive_whole_and_in_order_from_a_worker_process() -> None:
    with worker(answer_twice) as (requests, child):
        for size in (LARGE, LARGE // 2):
            requests.send(size)  # a request, as the pool sends it, on the same pipe
            assert requests.poll(TIMEOUT_SECONDS), "the worker never answered"
            status, data, pid = receive_answer(requests, TIMEOUT_SECONDS)
            assert (status, pid) == ("ok", child.pid)
            assert data == bytes(range(256)) * (size // 256)
        assert receive_answer(requests, TIMEOUT_SECONDS) == ("ok", None)
        child.join(TIMEOUT_SECONDS)
        assert child.exitcode == 0
        with pytest.raises(EOFError):
            receive_answer(requests, TIMEOUT_SECONDS)  # the worker's end left with it


def test_an_answer_cut_short_by_a_worker_that_leaves_is_an_eof_error_not_a_partial_answer() -> None:
    with worker(answer_short) as (requests, child):
        requests.send("begin")
        assert requests.poll(TIMEOUT_SECONDS), "the worker never began its answer"
        with pytest.raises(EOFError, match="524288 bytes short"):
            receive_answer(requests, TIMEOUT_SECONDS)
        child.join(TIMEOUT_SECONDS)
        assert child.exitcode == 0


def test_reading_an_answer_leaves_the_pipe_blocking_and_open_whatever_the_default_socket_timeout() -> None:
    with worker(answer_twice) as (requests, _child):
        socket.setdefaulttimeout(5.0)  # a socket made now is non-blocking, and the pipe's flags are its own
        try:
            requests.send(1024)
            assert requests.poll(TIMEOUT_SECONDS), "the worker never answered"
            assert receive_answer(requests, TIMEOUT_SECONDS)[0] == "ok"
            assert os.get_blocking(requests.fileno()), "the pipe was left non-blocking"
            requests.send(1024)  # the descriptor is the connection's still
            assert receive_answer(requests, TIMEOUT_SECONDS)[0] == "ok"
        finally:
            socket.setdefaulttimeout(None)


def test_an_answer_stopped_halfway_times_out_and_leaves_the_pipe_blocking_without_a_deadline() -> None:
    with worker(answer_halfway_and_hang) as (requests, child):
        requests.send("begin")
        assert requests.poll(TIMEOUT_SECONDS), "the worker never began its answer"
        began = time.monotonic()
        with pytest.raises(TimeoutError, match="524288 bytes short"):
            receive_answer(requests, 0.5)
        assert 0.5 <= time.monotonic() - began < TIMEOUT_SECONDS / 2
        assert child.is_alive(), "the worker left: this was an end of file, not a timeout"
        assert os.get_blocking(requests.fileno()), "the pipe was left non-blocking"
        lent = socket.socket(fileno=requests.fileno())
        try:  # the deadline was the read's own: the pipe's later reads wait as long as they must
            assert lent.getsockopt(socket.SOL_SOCKET, socket.SO_RCVTIMEO, 16) == bytes(16)
        finally:
            lent.detach()
