#!/usr/bin/python3
"""Serialize or deserialize DiagnosticArrays with genpy (Debian's python3-diagnostic-msgs) for tests.

Run by /usr/bin/python3, never by the project's venv. Messages travel as JSON: a list of
{"seq", "stamp_sec", "stamp_nanosec", "frame_id", "statuses": [[level, name, message, hardware_id,
[[key, value], ...]], ...]}, with `level` as the unsigned wire octet (genpy's `byte` is an int8).

  genpy_messages.py serialize    JSON messages on stdin; one hex payload per line on stdout
  genpy_messages.py deserialize  a JSON list of hex payloads on stdin; JSON messages on stdout
"""

from __future__ import annotations

import io
import json
import sys
from typing import Any

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue


def to_genpy(message: dict[str, Any]) -> Any:
    """The genpy message for one JSON message."""
    array = DiagnosticArray()
    array.header.seq = message["seq"]
    array.header.stamp.secs = message["stamp_sec"]
    array.header.stamp.nsecs = message["stamp_nanosec"]
    array.header.frame_id = message["frame_id"]
    array.status = [
        DiagnosticStatus(
            level=level - 256 if level > 127 else level,
            name=name,
            message=text,
            hardware_id=hardware_id,
            values=[KeyValue(key=key, value=value) for key, value in values],
        )
        for level, name, text, hardware_id, values in message["statuses"]
    ]
    return array


def from_genpy(array: Any) -> dict[str, Any]:
    """The JSON message for one genpy message."""
    return {
        "seq": array.header.seq,
        "stamp_sec": array.header.stamp.secs,
        "stamp_nanosec": array.header.stamp.nsecs,
        "frame_id": array.header.frame_id,
        "statuses": [
            [s.level & 0xFF, s.name, s.message, s.hardware_id, [[v.key, v.value] for v in s.values]]
            for s in array.status
        ],
    }


def main() -> None:
    """Run the mode named by the first argument."""
    mode = sys.argv[1]
    items = json.load(sys.stdin)
    if mode == "serialize":
        for message in items:
            buffer = io.BytesIO()
            to_genpy(message).serialize(buffer)
            print(buffer.getvalue().hex())
    elif mode == "deserialize":
        messages = [from_genpy(DiagnosticArray().deserialize(bytes.fromhex(text))) for text in items]
        json.dump(messages, sys.stdout)
    else:
        sys.exit(f"unknown mode {mode!r}: use serialize or deserialize")


if __name__ == "__main__":
    main()
