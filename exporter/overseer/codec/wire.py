"""What the codecs share: an array's header read apart from its statuses, and how a format is laid out.

Reading the header first and then one status at a time lets an ingest decode only the statuses that
changed since a robot's last array (`overseer.ingest`).
"""

from __future__ import annotations

from array import array
from collections.abc import Callable
from typing import NamedTuple

from overseer.codec import compiled
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
    layout = compiled.LAYOUTS.get(read_status)
    if layout is not None:
        # read_head bounded the count by the payload's size, so this allocation is bounded too.
        bounds = array("I", bytes(4 * (head.status_count + 1)))
        statuses = compiled.read_statuses(layout, payload, pos, end, bounds)
        pos = bounds[-1]
    else:
        bounds = array("I", [pos])
        statuses = _read_statuses(read_status, payload, pos, end, head.status_count, bounds)
        pos = bounds[-1]
    if wire.exact_end and pos != end:
        raise DecodeError(f"{end - pos} bytes left over after the message")
    decoded = DiagnosticArray(head.stamp_sec, head.stamp_nanosec, head.frame_id, statuses)
    return LaidOut(decoded, bounds, read_status)


def _read_statuses(
    read_status: StatusReader, payload: bytes, pos: int, end: int, count: int, bounds: array[int]
) -> tuple[DiagnosticStatus, ...]:
    """`count` statuses from `pos`, appending where each ended to `bounds` (the pure-Python path)."""
    statuses: list[DiagnosticStatus] = []
    append = statuses.append
    for _ in range(count):
        status, pos = read_status(payload, pos, end)
        append(status)
        bounds.append(pos)
    return tuple(statuses)
