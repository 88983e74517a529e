"""What the codecs share: an array's header read apart from its statuses, and how a format is laid out.

Reading the header first and then one status at a time lets an ingest decode only the statuses that
changed since a robot's last array (`overseer.sources.ingest`).
"""

from __future__ import annotations

from array import array
from collections.abc import Callable
from typing import NamedTuple

from overseer.codec.errors import DecodeError
from overseer.messages import DiagnosticArray, DiagnosticStatus

# Reads the status at a position, bounded by an end; returns it and the position after it.
StatusReader = Callable[[bytes, int, int], tuple[DiagnosticStatus, int]]


class ArrayHead(NamedTuple):
    """A serialized array's header, and how to read the statuses that follow it."""

    stamp_sec: int
    stamp_nanosec: int
    frame_id: str
    status_count: int
    statuses_at: int
    read_status: StatusReader


class WireFormat(NamedTuple):
    """One serialization of DiagnosticArray, as an ingest needs to know it."""

    read_head: Callable[[bytes], ArrayHead]
    stamp: tuple[int, int]  # the bytes that differ between republications of one array (seq, stamp)
    alignment: int  # a status decodes alike wherever it starts at the same offset modulo this
    exact_end: bool  # bytes after the last status are an error


def decode_array(wire: WireFormat, payload: bytes) -> DiagnosticArray:
    """Decode a whole payload in `wire`'s format."""
    return decode_laid_out(wire, payload).decoded


class LaidOut(NamedTuple):
    """A decoded array, where each of its statuses began and the last one ended, and their reader."""

    decoded: DiagnosticArray
    bounds: array[int]
    read_status: StatusReader


def decode_laid_out(wire: WireFormat, payload: bytes) -> LaidOut:
    """Decode a whole payload in `wire`'s format, keeping the statuses' positions."""
    head = wire.read_head(payload)
    end = len(payload)
    read_status = head.read_status
    pos = head.statuses_at
    bounds = array("I", [pos])
    statuses: list[DiagnosticStatus] = []
    append = statuses.append
    for _ in range(head.status_count):
        status, pos = read_status(payload, pos, end)
        append(status)
        bounds.append(pos)
    if wire.exact_end and pos != end:
        raise DecodeError(f"{end - pos} bytes left over after the message")
    decoded = DiagnosticArray(head.stamp_sec, head.stamp_nanosec, head.frame_id, tuple(statuses))
    return LaidOut(decoded, bounds, read_status)
