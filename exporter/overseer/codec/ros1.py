"""ROS 1 serialization of diagnostic_msgs/DiagnosticArray, as genpy and roscpp write it.

Little endian, no alignment, strings as a uint32 length and UTF-8 bytes with no terminator.
Decoding is strict and bounded like the CDR codec: every length is checked against the bytes that
remain before anything is allocated, and bytes left over after the message are an error, so a
garbled TCPROS frame ends in `DecodeError` rather than in a half-true message.
"""

from __future__ import annotations

import struct
from sys import intern  # names, messages, hardware_ids and keys repeat across a fleet: one copy each

from overseer.codec import compiled
from overseer.codec.errors import DecodeError
from overseer.codec.wire import ArrayHead, WireFormat, decode_array
from overseer.messages import DiagnosticArray, DiagnosticStatus

MESSAGE_TYPE = "diagnostic_msgs/DiagnosticArray"
MD5SUM = "60810da900de1dd6ddd437c3503511da"

_U32 = struct.Struct("<I")
_HEADER = struct.Struct("<3I")  # seq, stamp.secs, stamp.nsecs
_unpack_u32 = _U32.unpack_from

# Smallest encodings, used to bound a sequence count before allocating for it.
_MIN_STATUS_BYTES = 17  # level, three empty strings, empty values sequence
_MIN_KEY_VALUE_BYTES = 8  # two empty strings


def decode_diagnostic_array(payload: bytes) -> DiagnosticArray:
    """Decode one serialized DiagnosticArray (a TCPROS frame's body); the header's seq is dropped."""
    return decode_array(WIRE_FORMAT, payload)


def read_head(payload: bytes) -> ArrayHead:
    """The array's header and status count."""
    end = len(payload)
    if end < _HEADER.size:
        raise DecodeError(f"payload of {end} bytes is shorter than a header")
    _seq, sec, nanosec = _HEADER.unpack_from(payload)
    frame_id, pos = _read_string(payload, _HEADER.size, end)
    count, pos = _read_count(payload, pos, end, _MIN_STATUS_BYTES, "status")
    return ArrayHead(
        sec, nanosec, frame_id, count, pos, compiled.READERS["ros1"] if compiled.enabled else read_status
    )


def read_status(payload: bytes, pos: int, end: int) -> tuple[DiagnosticStatus, int]:
    """The status at `pos`, and the position after it."""
    if pos >= end:
        raise DecodeError("payload ends inside a status")
    level = payload[pos]
    name, pos = _read_string(payload, pos + 1, end)
    message, pos = _read_string(payload, pos, end)
    hardware_id, pos = _read_string(payload, pos, end)
    name, message, hardware_id = intern(name), intern(message), intern(hardware_id)
    value_count, pos = _read_count(payload, pos, end, _MIN_KEY_VALUE_BYTES, "value")
    values: list[tuple[str, str]] = []
    for _ in range(value_count):
        key, pos = _read_string(payload, pos, end)
        value, pos = _read_string(payload, pos, end)
        values.append((intern(key), value))
    return DiagnosticStatus(level, name, message, hardware_id, tuple(values)), pos


def _read_count(payload: bytes, pos: int, end: int, min_item_bytes: int, what: str) -> tuple[int, int]:
    if pos + 4 > end:
        raise DecodeError(f"payload ends before a {what} count")
    (count,) = _unpack_u32(payload, pos)
    pos += 4
    if count * min_item_bytes > end - pos:
        raise DecodeError(f"{what} count {count} runs past the payload")
    return count, pos


def _read_string(payload: bytes, pos: int, end: int) -> tuple[str, int]:
    if pos + 4 > end:
        raise DecodeError("payload ends before a string length")
    (length,) = _unpack_u32(payload, pos)
    pos += 4
    stop = pos + length
    if stop > end:
        raise DecodeError(f"string length {length} runs past the payload")
    return payload[pos:stop].decode("utf-8", "replace"), stop


# No alignment; the header's seq and stamp change in every republished array.
WIRE_FORMAT = WireFormat(read_head, stamp=(0, 12), alignment=1, exact_end=True)


def encode_diagnostic_array(array: DiagnosticArray, seq: int = 0) -> bytes:
    """Serialize a DiagnosticArray as a ROS 1 publisher does, with header sequence number `seq`."""
    out = bytearray(_HEADER.pack(seq, array.stamp_sec, array.stamp_nanosec))
    pack_u32 = _U32.pack

    def put_string(text: str) -> None:
        raw = text.encode("utf-8")
        out.extend(pack_u32(len(raw)))
        out.extend(raw)

    put_string(array.frame_id)
    out.extend(pack_u32(len(array.statuses)))
    for status in array.statuses:
        out.append(status.level & 0xFF)
        put_string(status.name)
        put_string(status.message)
        put_string(status.hardware_id)
        out.extend(pack_u32(len(status.values)))
        for key, value in status.values:
            put_string(key)
            put_string(value)
    return bytes(out)
