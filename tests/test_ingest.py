"""Payload ingest: decode and apply, skip unchanged republications, count what cannot be decoded."""

from __future__ import annotations

import pytest

from overseer.codec import DecodeError, ros1
from overseer.codec.cdr import decode_diagnostic_array, encode_diagnostic_array
from overseer.messages import DiagnosticArray, DiagnosticStatus
from overseer.model import FleetLimits, FleetModel
from overseer.sources.ingest import PayloadIngest
from overseer.sources.ros1 import ROS1_STAMP


def payload(stamp: int, level: int) -> bytes:
    return encode_diagnostic_array(
        DiagnosticArray(stamp, 0, "", (DiagnosticStatus(level, "/a", "m", "", ()),))
    )


def test_republished_payload_only_refreshes_and_changed_one_is_applied() -> None:
    model = FleetModel()
    decoded: list[bytes] = []

    def decode(data: bytes) -> DiagnosticArray:
        decoded.append(data)
        return decode_diagnostic_array(data)

    ingest = PayloadIngest(model, "r1", "dds", "rt/r1/diagnostics_agg", decode, (4, 12))
    for stamp in (1, 2, 3):
        ingest(payload(stamp, 0))
    assert len(decoded) == 1
    ingest(payload(4, 2))
    assert len(decoded) == 2
    snapshot = model.snapshot()
    assert snapshot.message_counts[("dds", "received")] == 4
    assert snapshot.robots[0].components[("/a", "")].level == 2


def test_undecodable_payload_is_counted_and_the_next_good_one_applies() -> None:
    model = FleetModel()
    ingest = PayloadIngest(model, "r1", "dds", "t", decode_diagnostic_array, (4, 12))
    with pytest.raises(DecodeError):
        ingest(b"\x00\x01\x00\x00garbage")
    ingest(payload(1, 1))
    snapshot = model.snapshot()
    assert snapshot.message_counts[("dds", "decode_error")] == 1
    assert snapshot.message_counts[("dds", "received")] == 1


def test_repeat_after_the_robot_was_forgotten_is_applied_again() -> None:
    now = [1_700_000_000.0]
    model = FleetModel(FleetLimits(expire_after=60), clock=lambda: now[0])
    ingest = PayloadIngest(model, "r1", "dds", "t", decode_diagnostic_array, (4, 12))
    ingest(payload(1, 0))
    now[0] += 61
    assert model.expire() == ["r1"]
    ingest(payload(2, 0))
    assert [r.name for r in model.snapshot().robots] == ["r1"]


def test_ros1_republications_differ_only_in_seq_and_stamp() -> None:
    array = DiagnosticArray(1, 0, "", (DiagnosticStatus(1, "/a", "m", "", ()),))
    model = FleetModel()
    decoded: list[bytes] = []

    def decode(data: bytes) -> DiagnosticArray:
        decoded.append(data)
        return ros1.decode_diagnostic_array(data)

    ingest = PayloadIngest(model, "r1", "ros1", "/diagnostics_agg", decode, ROS1_STAMP)
    for seq in range(3):
        ingest(ros1.encode_diagnostic_array(array._replace(stamp_sec=seq), seq))
    ingest(ros1.encode_diagnostic_array(array._replace(frame_id="map"), 3))
    assert len(decoded) == 2
