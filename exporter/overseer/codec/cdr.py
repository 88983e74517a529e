"""ROS 2 CDR (XCDR1 and plain XCDR2, both byte orders) for diagnostic_msgs/msg/DiagnosticArray.

Decoding is strict and bounded: every length is checked against the bytes that remain before anything
is allocated, so a hostile payload costs at most its own size and ends in `DecodeError`.
DiagnosticArray has no 8-byte members and no optional or mutable members, so plain XCDR2 is laid out
exactly like XCDR1.
"""

from __future__ import annotations

import struct
from sys import intern  # names, messages, hardware_ids and keys repeat across a fleet: one copy each

from overseer.codec import compiled
from overseer.codec.errors import DecodeError
from overseer.codec.wire import ArrayHead, StatusReader, WireFormat, decode_array
from overseer.messages import DiagnosticArray, DiagnosticStatus

ENCAPSULATION_CDR_BE = b"\x00\x00\x00\x00"
ENCAPSULATION_CDR_LE = b"\x00\x01\x00\x00"

# Representation identifier → little endian?  CDR_BE, CDR_LE, PLAIN_CDR2_BE, PLAIN_CDR2_LE.
_REPRESENTATIONS = {b"\x00\x00": False, b"\x00\x01": True, b"\x00\x06": False, b"\x00\x07": True}

_U32_LE = struct.Struct("<I").unpack_from
_U32_BE = struct.Struct(">I").unpack_from
_TIME_LE = struct.Struct("<iI").unpack_from
_TIME_BE = struct.Struct(">iI").unpack_from

# Smallest encodings, used to bound a sequence count before allocating for it.
_MIN_STATUS_BYTES = 20  # level, padding, three empty strings, empty values sequence
_MIN_KEY_VALUE_BYTES = 8  # two empty strings


def decode_diagnostic_array(payload: bytes) -> DiagnosticArray:
    """Decode a serialized DiagnosticArray (with its 4-byte encapsulation header)."""
    return decode_array(WIRE_FORMAT, payload)


def read_head(payload: bytes) -> ArrayHead:
    """The array's header and status count, and the reader for its byte order."""
    end = len(payload)
    if end < 4:
        raise DecodeError(f"payload of {end} bytes is shorter than the encapsulation header")
    little = _REPRESENTATIONS.get(payload[:2])
    if little is None:
        raise DecodeError(f"unsupported encapsulation {payload[:2].hex()}")
    u32 = _U32_LE if little else _U32_BE
    if end < 16:
        raise DecodeError("payload too short for a header")
    sec, nanosec = (_TIME_LE if little else _TIME_BE)(payload, 4)
    frame_id, pos = read_string(payload, 12, end, u32)
    pos = (pos + 3) & ~3
    if pos + 4 > end:
        raise DecodeError("payload ends before the status sequence")
    (count,) = u32(payload, pos)
    pos += 4
    if count * _MIN_STATUS_BYTES > end - pos:
        raise DecodeError(f"status count {count} runs past the payload")
    if compiled.enabled:
        read_status = compiled.READERS["cdr_le" if little else "cdr_be"]
    else:
        read_status = _READ_STATUS_LE if little else _READ_STATUS_BE
    return ArrayHead(sec, nanosec, frame_id, count, pos, read_status)


def byte_order(payload: bytes) -> struct._UnpackFrom:  # type: ignore[name-defined]
    """The unsigned 32-bit reader of the payload's byte order, from its encapsulation header."""
    little = _REPRESENTATIONS.get(payload[:2]) if len(payload) >= 4 else None
    if little is None:
        raise DecodeError(f"unsupported encapsulation {payload[:2].hex()}")
    return _U32_LE if little else _U32_BE


def _status_reader(u32: struct._UnpackFrom) -> StatusReader:  # type: ignore[name-defined]
    def read_status(payload: bytes, pos: int, end: int) -> tuple[DiagnosticStatus, int]:
        if pos >= end:
            raise DecodeError("payload ends inside a status")
        level = payload[pos]
        name, pos = read_string(payload, pos + 1, end, u32)
        message, pos = read_string(payload, pos, end, u32)
        hardware_id, pos = read_string(payload, pos, end, u32)
        name, message, hardware_id = intern(name), intern(message), intern(hardware_id)
        pos = (pos + 3) & ~3
        if pos + 4 > end:
            raise DecodeError("payload ends before a values sequence")
        (value_count,) = u32(payload, pos)
        pos += 4
        if value_count * _MIN_KEY_VALUE_BYTES > end - pos:
            raise DecodeError(f"value count {value_count} runs past the payload")
        values: list[tuple[str, str]] = []
        for _ in range(value_count):
            key, pos = read_string(payload, pos, end, u32)
            value, pos = read_string(payload, pos, end, u32)
            values.append((intern(key), value))
        return DiagnosticStatus(level, name, message, hardware_id, tuple(values)), pos

    return read_status


def read_string(payload: bytes, pos: int, end: int, u32: struct._UnpackFrom) -> tuple[str, int]:  # type: ignore[name-defined]
    """Read a CDR string at `pos` (aligning first); returns the text and the position after it.

    Invalid UTF-8 becomes U+FFFD; a string that is not NUL-terminated, or runs past `end`, is a DecodeError.
    """
    pos = (pos + 3) & ~3
    if pos + 4 > end:
        raise DecodeError("payload ends before a string length")
    (length,) = u32(payload, pos)
    pos += 4
    if length == 0:
        return "", pos
    stop = pos + length
    if stop > end:
        raise DecodeError(f"string length {length} runs past the payload")
    if payload[stop - 1] != 0:
        raise DecodeError("string is not NUL-terminated")
    return payload[pos : stop - 1].decode("utf-8", "replace"), stop


_READ_STATUS_LE = _status_reader(_U32_LE)
_READ_STATUS_BE = _status_reader(_U32_BE)

# CDR aligns to 4 bytes from the start of the data; the stamp follows the encapsulation header.
WIRE_FORMAT = WireFormat(read_head, stamp=(4, 12), alignment=4, exact_end=False)


def encode_diagnostic_array(array: DiagnosticArray, *, little_endian: bool = True) -> bytes:
    """Serialize a DiagnosticArray as XCDR1 with its encapsulation header, as ROS 2 writers do."""
    order = "<" if little_endian else ">"
    u32 = struct.Struct(order + "I").pack
    out = bytearray(ENCAPSULATION_CDR_LE if little_endian else ENCAPSULATION_CDR_BE)
    out += struct.pack(order + "iI", array.stamp_sec, array.stamp_nanosec)

    def put_string(text: str) -> None:
        out.extend(b"\x00" * (-len(out) & 3))
        raw = text.encode("utf-8")
        out.extend(u32(len(raw) + 1))
        out.extend(raw)
        out.append(0)

    put_string(array.frame_id)
    out.extend(b"\x00" * (-len(out) & 3))
    out.extend(u32(len(array.statuses)))
    for status in array.statuses:
        out.append(status.level & 0xFF)
        put_string(status.name)
        put_string(status.message)
        put_string(status.hardware_id)
        out.extend(b"\x00" * (-len(out) & 3))
        out.extend(u32(len(status.values)))
        for key, value in status.values:
            put_string(key)
            put_string(value)
    return bytes(out)
