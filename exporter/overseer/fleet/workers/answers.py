"""A worker's answers to the exporter, on the request pipe's socket, each read whole in one call.

A multiprocessing `Connection` reads a message in as many reads as the socket holds at a time (a couple
of hundred kilobytes), and each read gives up the interpreter lock and waits for it again. Beside the
exporter's busy threads (the Zenoh relay's) each wait lasts up to the switch interval (5 ms): the 8 MB
exposition part of a worker of 5,000 robots took 0.06-0.4 s to read that way beside one or two busy
threads, and a scrape waits for it. Read with `MSG_WAITALL` the kernel fills the whole answer before the
call returns: one wait. A worker stopped halfway through an answer (by a signal, or swapped out for
good) would keep that call waiting forever: the kernel gives it a deadline of its own (`SO_RCVTIMEO`,
which leaves the descriptor blocking), and it ends in a TimeoutError.

An answer is its pickle's length (8 bytes) and the pickle. The requests still go the other way as
`Connection` messages: each direction has one framing of its own. The pipe joins two processes of one
exporter, so what it carries is trusted as the exporter's own objects are.
"""

from __future__ import annotations

import os
import pickle
import socket
import struct
import time
from multiprocessing.connection import Connection
from typing import Any

_LENGTH = struct.Struct("!Q")
_TIMEVAL = struct.Struct("@ll")  # struct timeval, as SO_RCVTIMEO takes it on Linux
_NO_DEADLINE = _TIMEVAL.pack(0, 0)


def send_answer(connection: Connection, answer: Any) -> None:
    """Write `answer` to the exporter's end of `connection` (OSError once it is gone)."""
    data = pickle.dumps(answer, protocol=pickle.HIGHEST_PROTOCOL)
    descriptor = connection.fileno()
    _write_all(descriptor, _LENGTH.pack(len(data)))
    _write_all(descriptor, data)


def receive_answer(connection: Connection, timeout: float) -> Any:
    """The next answer a worker wrote to `connection`, read within `timeout` seconds once begun.

    EOFError when the worker closed its end first; TimeoutError when the whole answer did not arrive in
    time (the pipe is then out of step: the caller gives the worker up).
    """
    reader = socket.socket(fileno=connection.fileno())  # the same descriptor, lent for this answer
    deadline = time.monotonic() + timeout
    try:
        reader.settimeout(None)  # blocking, whatever `socket.setdefaulttimeout` says (it is the pipe's too)
        (length,) = _LENGTH.unpack(_read_exactly(reader, _LENGTH.size, deadline))
        return pickle.loads(_read_exactly(reader, length, deadline))  # written by this exporter's own worker
    finally:
        try:
            reader.setsockopt(socket.SOL_SOCKET, socket.SO_RCVTIMEO, _NO_DEADLINE)
        finally:
            reader.detach()  # the connection keeps its descriptor


def _write_all(descriptor: int, data: bytes) -> None:
    # A blocking socket's write returns once all of it is queued but for a signal: rarely a second call.
    view = memoryview(data)
    while view:
        view = view[os.write(descriptor, view) :]


def _read_exactly(reader: socket.socket, length: int, deadline: float) -> bytearray:
    buffer = bytearray(length)
    view = memoryview(buffer)
    filled = 0
    while filled < length:  # short only when a signal came, the deadline passed or the writer left
        remaining = deadline - time.monotonic()
        if remaining <= 0:
            raise TimeoutError(f"a worker's answer stopped {length - filled} bytes short of its end")
        seconds, fraction = divmod(remaining, 1.0)
        limit = _TIMEVAL.pack(int(seconds), max(1, int(fraction * 1e6)))  # all zero would mean none
        reader.setsockopt(socket.SOL_SOCKET, socket.SO_RCVTIMEO, limit)
        try:
            received = reader.recv_into(view[filled:], length - filled, socket.MSG_WAITALL)
        except BlockingIOError:  # the deadline passed before a byte came
            continue
        if not received:
            raise EOFError(f"the worker closed its pipe {length - filled} bytes short of an answer")
        filled += received
    return buffer
