"""The ROS 1 codec, byte for byte against genpy (Debian's diagnostic_msgs) and rosbags' Noetic typestore."""

from __future__ import annotations

import contextlib
import struct
from collections.abc import Iterator
from typing import Any

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from rosbags.typesys import Stores, get_typestore

from overseer.codec import DecodeError
from overseer.codec.ros1 import decode_diagnostic_array, encode_diagnostic_array
from overseer.messages import DiagnosticArray, DiagnosticStatus
from support import strategies
from support.codec_paths import CODEC_PATHS, codec_path
from support.examples import examples
from testbed.ros1 import genpy

MESSAGE_TYPE = "diagnostic_msgs/msg/DiagnosticArray"


@pytest.fixture(autouse=True, scope="module", params=CODEC_PATHS)
def codec(request: pytest.FixtureRequest) -> Iterator[str]:
    """Every test of this module runs once with each status decoder."""
    with codec_path(request.param):
        yield request.param


# name → (message, header seq)
EXAMPLES: dict[str, tuple[DiagnosticArray, int]] = {
    "empty array": (DiagnosticArray(0, 0, "", ()), 0),
    "empty strings and values": (DiagnosticArray(1, 2, "", (DiagnosticStatus(0, "", "", "", ()),)), 1),
    "paper robot": (
        DiagnosticArray(
            1_700_000_000,
            999_999_999,
            "base_link",
            (
                DiagnosticStatus(
                    0, "/Power/Robot Battery", "Charge OK", "bms", (("voltage", "12.4"), ("percent", "88"))
                ),
                DiagnosticStatus(1, "/Temp/Sensor1", "Warm", "t1", (("temperature", "71.5"),)),
                DiagnosticStatus(2, "/Camera/Cam1", "No frames", "", ()),
                DiagnosticStatus(3, "/Laser", "Stale", "", ()),
            ),
        ),
        4_000_000_000,
    ),
    "non-ASCII text": (
        DiagnosticArray(
            5,
            7,
            "ロボット",
            (DiagnosticStatus(1, "/Température/Capteur ☃", "très chaud 🔥", "ß", (("ключ", "значение"),)),),
        ),
        9,
    ),
    "hostile names and NUL bytes": (
        DiagnosticArray(
            0,
            0,
            "a\x00b",
            (DiagnosticStatus(2, 'a"b\\c\nd{e}=f,', "x\ty\r\n\x00", "\x01", (('k"\\\n', "v"),)),),
        ),
        0,
    ),
    "levels outside 0..3": (
        DiagnosticArray(
            0, 0, "", tuple(DiagnosticStatus(level, f"/L{level}", "", "", ()) for level in (4, 127, 128, 255))
        ),
        0,
    ),
    "large array": (
        DiagnosticArray(
            3,
            4,
            "f",
            tuple(
                DiagnosticStatus(
                    i % 4,
                    f"/Group{i % 7}/Component{i}",
                    "m" * (i % 5),
                    f"hw{i}",
                    (("value", str(i)),) * (i % 3),
                )
                for i in range(10_000)
            ),
        ),
        12,
    ),
}


def as_json(array: DiagnosticArray, seq: int) -> dict[str, Any]:
    """The message in testbed/ros1/genpy_messages.py's JSON form."""
    return {
        "seq": seq,
        "stamp_sec": array.stamp_sec,
        "stamp_nanosec": array.stamp_nanosec,
        "frame_id": array.frame_id,
        "statuses": [
            [s.level, s.name, s.message, s.hardware_id, [list(v) for v in s.values]] for s in array.statuses
        ],
    }


def to_rosbags(store: Any, array: DiagnosticArray, seq: int) -> Any:
    """The same message as a rosbags object (whose `byte` is an int8, as in genpy)."""
    types = store.types
    return types[MESSAGE_TYPE](
        header=types["std_msgs/msg/Header"](
            seq=seq,
            stamp=types["builtin_interfaces/msg/Time"](sec=array.stamp_sec, nanosec=array.stamp_nanosec),
            frame_id=array.frame_id,
        ),
        status=[
            types["diagnostic_msgs/msg/DiagnosticStatus"](
                level=s.level - 256 if s.level > 127 else s.level,
                name=s.name,
                message=s.message,
                hardware_id=s.hardware_id,
                values=[types["diagnostic_msgs/msg/KeyValue"](key=k, value=v) for k, v in s.values],
            )
            for s in array.statuses
        ],
    )


@pytest.fixture(scope="module")
def genpy_payloads() -> dict[str, bytes]:
    """Every example serialized by genpy, in one run of /usr/bin/python3."""
    payloads = genpy("serialize", [as_json(array, seq) for array, seq in EXAMPLES.values()])
    return dict(zip(EXAMPLES, payloads, strict=True))


@pytest.fixture(scope="module")
def noetic() -> Any:
    return get_typestore(Stores.ROS1_NOETIC)


@pytest.mark.parametrize("example", list(EXAMPLES))
def test_encoding_matches_genpy_byte_for_byte(genpy_payloads: dict[str, bytes], example: str) -> None:
    array, seq = EXAMPLES[example]
    assert encode_diagnostic_array(array, seq) == genpy_payloads[example]


@pytest.mark.parametrize("example", list(EXAMPLES))
def test_decoding_genpy_payload_gives_the_message_back(
    genpy_payloads: dict[str, bytes], example: str
) -> None:
    assert decode_diagnostic_array(genpy_payloads[example]) == EXAMPLES[example][0]


def test_genpy_decodes_our_encoding() -> None:
    payloads = [encode_diagnostic_array(array, seq).hex() for array, seq in EXAMPLES.values()]
    assert genpy("deserialize", payloads) == [as_json(array, seq) for array, seq in EXAMPLES.values()]


@pytest.mark.parametrize("example", list(EXAMPLES))
def test_encoding_matches_rosbags_byte_for_byte(noetic: Any, example: str) -> None:
    array, seq = EXAMPLES[example]
    expected = bytes(noetic.serialize_ros1(to_rosbags(noetic, array, seq), MESSAGE_TYPE))
    assert encode_diagnostic_array(array, seq) == expected


@pytest.mark.parametrize("example", list(EXAMPLES))
def test_decoding_rosbags_payload_gives_the_message_back(noetic: Any, example: str) -> None:
    array, seq = EXAMPLES[example]
    payload = bytes(noetic.serialize_ros1(to_rosbags(noetic, array, seq), MESSAGE_TYPE))
    assert decode_diagnostic_array(payload) == array


def test_stamp_after_2038_is_unsigned_as_in_genpy() -> None:
    array = DiagnosticArray(3_000_000_000, 1, "", ())
    (payload,) = genpy("serialize", [as_json(array, 0)])
    assert decode_diagnostic_array(payload).stamp_sec == 3_000_000_000


def test_invalid_utf8_is_replaced_not_rejected() -> None:
    payload = bytearray(
        encode_diagnostic_array(DiagnosticArray(0, 0, "", (DiagnosticStatus(0, "ab", "", "", ()),)))
    )
    payload[payload.index(b"ab")] = 0xFF
    assert decode_diagnostic_array(bytes(payload)).statuses[0].name == "\ufffdb"


def test_every_truncation_is_a_decode_error() -> None:
    payload = encode_diagnostic_array(EXAMPLES["paper robot"][0])
    for length in range(len(payload)):
        with pytest.raises(DecodeError):
            decode_diagnostic_array(payload[:length])


def test_trailing_bytes_are_a_decode_error() -> None:
    payload = encode_diagnostic_array(EXAMPLES["paper robot"][0])
    with pytest.raises(DecodeError, match="left over"):
        decode_diagnostic_array(payload + b"\x00")


def test_lying_status_count_is_rejected_before_allocating() -> None:
    header = struct.pack("<3I", 0, 0, 0) + struct.pack("<I", 0)
    with pytest.raises(DecodeError, match="status count"):
        decode_diagnostic_array(header + struct.pack("<I", 0xFFFFFFFF) + b"\x00" * 64)


def test_lying_value_count_is_rejected_before_allocating() -> None:
    payload = encode_diagnostic_array(DiagnosticArray(0, 0, "", (DiagnosticStatus(0, "n", "", "", ()),)))
    with pytest.raises(DecodeError, match="value count"):
        decode_diagnostic_array(payload[:-4] + struct.pack("<I", 0x40000000) + b"\x00" * 64)


def test_lying_string_length_is_a_decode_error() -> None:
    payload = bytearray(encode_diagnostic_array(EXAMPLES["paper robot"][0]))
    struct.pack_into("<I", payload, 12, 0x7FFFFFFF)  # the frame_id length
    with pytest.raises(DecodeError, match="runs past"):
        decode_diagnostic_array(bytes(payload))


@settings(max_examples=examples(300), deadline=None)
@given(st.binary(max_size=512))
def test_random_bytes_raise_only_decode_error(data: bytes) -> None:
    for payload in (data, struct.pack("<3I", 0, 0, 0) + data):
        with contextlib.suppress(DecodeError):
            decode_diagnostic_array(payload)


@settings(max_examples=examples(200), deadline=None)
@given(st.binary(min_size=1, max_size=64), st.integers(min_value=0, max_value=200))
def test_corrupted_payloads_raise_only_decode_error(noise: bytes, offset: int) -> None:
    payload = bytearray(encode_diagnostic_array(EXAMPLES["paper robot"][0]))
    start = offset % len(payload)
    payload[start : start + len(noise)] = noise
    with contextlib.suppress(DecodeError):
        decode_diagnostic_array(bytes(payload))


arrays = strategies.arrays(st.integers(min_value=0, max_value=2**32 - 1))


@settings(max_examples=examples(200), deadline=None)
@given(arrays, st.integers(min_value=0, max_value=2**32 - 1))
def test_roundtrip_of_any_message(array: DiagnosticArray, seq: int) -> None:
    assert decode_diagnostic_array(encode_diagnostic_array(array, seq)) == array
