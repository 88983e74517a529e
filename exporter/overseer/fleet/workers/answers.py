"""A worker's answers to the exporter, on the request pipe's socket, each read whole in one call.

A multiprocessing `Connection` reads a message in as many reads as the socket holds at a time (a couple
of hundred kilobytes), and each read gives up the interpreter lock and waits for it again. Beside the
exporter's busy threads (the Zenoh relay's) each wait lasts up to the switch interval (5 ms): the 8 MB
exposition part of a worker of 5,000 robots took 0.06-0.4 s to read that way beside one or two busy
threads, and a scrape waits for it. Read with `MSG_WAITALL` the kernel fills the whole answer before the
call returns: one wait.

An answer is its pickle's length (8 bytes) and the pickle. The requests still go the other way as
`Connection` messages: each direction has one framing of its own. The pipe joins two processes of one
exporter, so what it carries is trusted as the exporter's own objects are.
"""

from __future__ import annotations

import os
import pickle
import socket
import struct
from multiprocessing.connection import Connection
from typing import Any

_LENGTH = struct.Struct("!Q")


def send_answer(connection: Connection, answer: Any) -> None:
    """Write `answer` to the exporter's end of `connection` (OSError once it is gone)."""
    data = pickle.dumps(answer, protocol=pickle.HIGHEST_PROTOCOL)
    descriptor = connection.fileno()
    _write_all(descriptor, _LENGTH.pack(len(data)))
    _write_all(descriptor, data)


def receive_answer(connection: Connection) -> Any:
    """The next answer a worker wrote to `connection` (EOFError when it closed its end first)."""
    reader = socket.socket(fileno=connection.fileno())  # the same descriptor, lent for this answer
    try:
        reader.settimeout(None)  # blocking, whatever `socket.setdefaulttimeout` says (it is the pipe's too)
        (length,) = _LENGTH.unpack(_read_exactly(reader, _LENGTH.size))
        return pickle.loads(_read_exactly(reader, length))  # written by this exporter's own worker
    finally:
        reader.detach()  # the connection keeps its descriptor


def _write_all(descriptor: int, data: bytes) -> None:
    # A blocking socket's write returns once all of it is queued but for a signal: rarely a second call.
    view = memoryview(data)
    while view:
        view = view[os.write(descriptor, view) :]


def _read_exactly(reader: socket.socket, length: int) -> bytearray:
    buffer = bytearray(length)
    view = memoryview(buffer)
    filled = 0
    while filled < length:  # short only when a signal came or the writer closed its end
        received = reader.recv_into(view[filled:], length - filled, socket.MSG_WAITALL)
        if not received:
            raise EOFError(f"the worker closed its pipe {length - filled} bytes short of an answer")
        filled += received
    return buffer
