"""Payload ingest: decode and apply, skip unchanged republications, count what cannot be decoded."""

from __future__ import annotations

from overseer.codec.cdr import decode_diagnostic_array, encode_diagnostic_array
from overseer.messages import DiagnosticArray, DiagnosticStatus
from overseer.model import FleetLimits, FleetModel
from overseer.sources.ingest import PayloadIngest


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
    assert ingest(payload(1, 0)) and ingest(payload(2, 0)) and ingest(payload(3, 0))
    assert len(decoded) == 1
    assert ingest(payload(4, 2))
    assert len(decoded) == 2
    snapshot = model.snapshot()
    assert snapshot.message_counts[("dds", "received")] == 4
    assert snapshot.robots[0].components[("/a", "")].level == 2


def test_undecodable_payload_is_counted_and_the_next_good_one_applies() -> None:
    model = FleetModel()
    ingest = PayloadIngest(model, "r1", "dds", "t", decode_diagnostic_array, (4, 12))
    assert not ingest(b"\x00\x01\x00\x00garbage")
    assert ingest(payload(1, 1))
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
