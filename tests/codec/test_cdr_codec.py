"""The ROS 2 CDR codec, byte for byte against rosbags' Jazzy and Humble typestores."""

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
from overseer.codec.cdr import decode_diagnostic_array, encode_diagnostic_array
from overseer.messages import DiagnosticArray, DiagnosticStatus
from support import strategies
from support.codec_paths import CODEC_PATHS, codec_path
from support.examples import examples

MESSAGE_TYPE = "diagnostic_msgs/msg/DiagnosticArray"
STORES = [Stores.ROS2_JAZZY, Stores.ROS2_HUMBLE]


@pytest.fixture(autouse=True, scope="module", params=CODEC_PATHS)
def codec(request: pytest.FixtureRequest) -> Iterator[str]:
    """Every test of this module runs once with each status decoder."""
    with codec_path(request.param):
        yield request.param


def to_rosbags(store: Any, array: DiagnosticArray) -> Any:
    """The same message as a rosbags object of `store`."""
    types = store.types
    return types[MESSAGE_TYPE](
        header=types["std_msgs/msg/Header"](
            stamp=types["builtin_interfaces/msg/Time"](sec=array.stamp_sec, nanosec=array.stamp_nanosec),
            frame_id=array.frame_id,
        ),
        status=[
            types["diagnostic_msgs/msg/DiagnosticStatus"](
                level=s.level,
                name=s.name,
                message=s.message,
                hardware_id=s.hardware_id,
                values=[types["diagnostic_msgs/msg/KeyValue"](key=k, value=v) for k, v in s.values],
            )
            for s in array.statuses
        ],
    )


EXAMPLES = {
    "empty array": DiagnosticArray(0, 0, "", ()),
    "empty strings and values": DiagnosticArray(1, 2, "", (DiagnosticStatus(0, "", "", "", ()),)),
    "paper robot": DiagnosticArray(
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
    "non-ASCII text": DiagnosticArray(
        -5,
        7,
        "ロボット",
        (DiagnosticStatus(1, "/Température/Capteur ☃", "très chaud 🔥", "ß", (("ключ", "значение"),)),),
    ),
    "hostile names": DiagnosticArray(
        0, 0, "", (DiagnosticStatus(2, 'a"b\\c\nd{e}=f,', "x\ty\r\n", "\x01", (('k"\\\n', "v"),)),)
    ),
    "large array": DiagnosticArray(
        3,
        4,
        "f",
        tuple(
            DiagnosticStatus(
                i % 4, f"/Group{i % 7}/Component{i}", "m" * (i % 5), f"hw{i}", (("value", str(i)),) * (i % 3)
            )
            for i in range(10_000)
        ),
    ),
}


@pytest.mark.parametrize("store_name", STORES, ids=lambda s: s.name)
@pytest.mark.parametrize("little_endian", [True, False], ids=["little-endian", "big-endian"])
@pytest.mark.parametrize("example", list(EXAMPLES), ids=list(EXAMPLES))
def test_encoding_matches_rosbags_byte_for_byte(
    store_name: Stores, little_endian: bool, example: str
) -> None:
    store = get_typestore(store_name)
    array = EXAMPLES[example]
    expected = bytes(store.serialize_cdr(to_rosbags(store, array), MESSAGE_TYPE, little_endian=little_endian))
    assert encode_diagnostic_array(array, little_endian=little_endian) == expected


@pytest.mark.parametrize("store_name", STORES, ids=lambda s: s.name)
@pytest.mark.parametrize("little_endian", [True, False], ids=["little-endian", "big-endian"])
@pytest.mark.parametrize("example", list(EXAMPLES), ids=list(EXAMPLES))
def test_decoding_rosbags_payload_gives_the_message_back(
    store_name: Stores, little_endian: bool, example: str
) -> None:
    store = get_typestore(store_name)
    array = EXAMPLES[example]
    payload = bytes(store.serialize_cdr(to_rosbags(store, array), MESSAGE_TYPE, little_endian=little_endian))
    assert decode_diagnostic_array(payload) == array


def test_decoding_accepts_trailing_padding() -> None:
    payload = encode_diagnostic_array(EXAMPLES["paper robot"])
    assert decode_diagnostic_array(payload + b"\x00\x00\x00") == EXAMPLES["paper robot"]


def test_plain_xcdr2_decodes_like_xcdr1() -> None:
    payload = encode_diagnostic_array(EXAMPLES["paper robot"])
    assert decode_diagnostic_array(b"\x00\x07" + payload[2:]) == EXAMPLES["paper robot"]


def test_invalid_utf8_is_replaced_not_rejected() -> None:
    payload = bytearray(
        encode_diagnostic_array(DiagnosticArray(0, 0, "", (DiagnosticStatus(0, "ab", "", "", ()),)))
    )
    index = payload.index(b"ab")
    payload[index] = 0xFF
    assert decode_diagnostic_array(bytes(payload)).statuses[0].name == "\ufffdb"


def test_every_truncation_is_a_decode_error() -> None:
    payload = encode_diagnostic_array(EXAMPLES["paper robot"])
    for length in range(len(payload)):
        with pytest.raises(DecodeError):
            decode_diagnostic_array(payload[:length])


def test_unknown_encapsulation_is_a_decode_error() -> None:
    payload = encode_diagnostic_array(EXAMPLES["paper robot"])
    with pytest.raises(DecodeError, match="encapsulation"):
        decode_diagnostic_array(b"\x00\x0a" + payload[2:])


def test_lying_status_count_is_rejected_before_allocating() -> None:
    header = b"\x00\x01\x00\x00" + struct.pack("<iI", 0, 0) + struct.pack("<I", 1) + b"\x00\x00\x00\x00"
    with pytest.raises(DecodeError, match="status count"):
        decode_diagnostic_array(header + struct.pack("<I", 0xFFFFFFFF) + b"\x00" * 64)


def test_lying_string_length_is_a_decode_error() -> None:
    payload = bytearray(encode_diagnostic_array(EXAMPLES["paper robot"]))
    struct.pack_into("<I", payload, 12, 0x7FFFFFFF)  # the frame_id length
    with pytest.raises(DecodeError, match="runs past"):
        decode_diagnostic_array(bytes(payload))


def test_string_without_terminator_is_a_decode_error() -> None:
    payload = bytearray(encode_diagnostic_array(DiagnosticArray(0, 0, "abc", ())))
    payload[19] = ord("x")  # overwrite the NUL after "abc"
    with pytest.raises(DecodeError, match="NUL"):
        decode_diagnostic_array(bytes(payload))


@settings(max_examples=examples(300), deadline=None)
@given(st.binary(max_size=512))
def test_random_bytes_raise_only_decode_error(data: bytes) -> None:
    for payload in (data, b"\x00\x01\x00\x00" + data, b"\x00\x00\x00\x00" + data):
        with contextlib.suppress(DecodeError):
            decode_diagnostic_array(payload)


@settings(max_examples=examples(200), deadline=None)
@given(st.binary(min_size=1, max_size=64), st.integers(min_value=0, max_value=200))
def test_corrupted_payloads_raise_only_decode_error(noise: bytes, offset: int) -> None:
    payload = bytearray(encode_diagnostic_array(EXAMPLES["paper robot"]))
    start = offset % len(payload)
    payload[start : start + len(noise)] = noise
    with contextlib.suppress(DecodeError):
        decode_diagnostic_array(bytes(payload))


arrays = strategies.arrays(st.integers(min_value=-(2**31), max_value=2**31 - 1))


@settings(max_examples=examples(200), deadline=None)
@given(arrays, st.booleans())
def test_roundtrip_of_any_message(array: DiagnosticArray, little_endian: bool) -> None:
    clean = array._replace(
        frame_id=array.frame_id.replace("\x00", ""),
        statuses=tuple(
            s._replace(
                name=s.name.replace("\x00", ""),
                message=s.message.replace("\x00", ""),
                hardware_id=s.hardware_id.replace("\x00", ""),
                values=tuple((k.replace("\x00", ""), v.replace("\x00", "")) for k, v in s.values),
            )
            for s in array.statuses
        ),
    )
    assert decode_diagnostic_array(encode_diagnostic_array(clean, little_endian=little_endian)) == clean
