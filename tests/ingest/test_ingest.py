"""Payload ingest: skip republications, decode only the statuses that changed, count what is undecodable.

The property tests hold the ingest, which decodes and applies only what changed, to the plain path that
decodes every payload whole and applies it: after any sequence of payloads the two models must agree.
Every test runs with each status decoder; the plain path always decodes with the pure-Python reference.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from overseer.codec import DecodeError, cdr, ros1
from overseer.codec.wire import ArrayHead, WireFormat, decode_array, decode_laid_out
from overseer.ingest.payload import PayloadIngest
from overseer.messages import DiagnosticArray, DiagnosticStatus
from overseer.model import FleetLimits, FleetModel, FleetSnapshot
from support.clock import ManualClock
from support.codec_paths import CODEC_PATHS, codec_path
from support.examples import examples


@pytest.fixture(autouse=True, scope="module", params=CODEC_PATHS)
def codec(request: pytest.FixtureRequest) -> Iterator[str]:
    """Every test of this module runs once with each status decoder."""
    with codec_path(request.param):
        yield request.param


class CountingWire:
    """A wire format that counts the statuses it decodes."""

    def __init__(self, wire: WireFormat) -> None:
        self.decoded: list[str] = []
        self._wire = wire
        self.format = wire._replace(read_head=self._read_head)

    def _read_head(self, payload: bytes) -> ArrayHead:
        head = self._wire.read_head(payload)
        read_status = head.read_status

        def counted(data: bytes, pos: int, end: int) -> tuple[DiagnosticStatus, int]:
            status, after = read_status(data, pos, end)
            self.decoded.append(status.name)
            return status, after

        return head._replace(read_status=counted)


def statuses(*names_and_voltages: tuple[str, str]) -> tuple[DiagnosticStatus, ...]:
    return tuple(DiagnosticStatus(0, name, "ok", "", (("voltage", v),)) for name, v in names_and_voltages)


def cdr_payload(stamp: int, *items: DiagnosticStatus) -> bytes:
    return cdr.encode_diagnostic_array(DiagnosticArray(stamp, 0, "", items))


def test_republished_payload_only_refreshes_and_changed_one_is_applied() -> None:
    model = FleetModel()
    wire = CountingWire(cdr.WIRE_FORMAT)
    ingest = PayloadIngest(model, "r1", "dds", "rt/r1/diagnostics_agg", wire.format)
    for stamp in (1, 2, 3):
        ingest(cdr_payload(stamp, DiagnosticStatus(0, "/a", "m", "")))
    assert wire.decoded == ["/a"]
    ingest(cdr_payload(4, DiagnosticStatus(2, "/a", "m", "")))
    assert wire.decoded == ["/a", "/a"]
    snapshot = model.snapshot()
    assert snapshot.message_counts[("dds", "received")] == 4
    assert snapshot.robots[0].components[("/a", "")].level == 2


def test_a_payload_equal_but_for_its_encapsulation_header_is_read_again_not_taken_as_republished() -> None:
    model = FleetModel()
    ingest = PayloadIngest(model, "r1", "dds", "t", cdr.WIRE_FORMAT)
    payload = cdr_payload(1, DiagnosticStatus(1, "/a", "m", ""))
    ingest(payload)
    with pytest.raises(DecodeError):
        ingest(b"\xff\xff" + payload[2:])  # no representation this reader knows
    snapshot = model.snapshot()
    assert snapshot.message_counts[("dds", "decode_error")] == 1
    assert snapshot.message_counts[("dds", "received")] == 1


def test_only_the_statuses_that_changed_are_decoded() -> None:
    model = FleetModel()
    wire = CountingWire(cdr.WIRE_FORMAT)
    ingest = PayloadIngest(model, "r1", "dds", "t", wire.format)
    ingest(cdr_payload(1, *statuses(("/a", "1.0"), ("/b", "2.0"), ("/c", "3.0"))))
    wire.decoded.clear()
    ingest(cdr_payload(2, *statuses(("/a", "1.0"), ("/b", "2.5"), ("/c", "3.0"))))
    assert wire.decoded == ["/b"]
    components = model.snapshot().robots[0].components
    assert components[("/b", "")].values == (("voltage", "2.5"),)
    assert components[("/c", "")].values == (("voltage", "3.0"),)


def test_a_status_that_grows_out_of_alignment_makes_the_rest_decode_again() -> None:
    model = FleetModel()
    wire = CountingWire(cdr.WIRE_FORMAT)
    ingest = PayloadIngest(model, "r1", "dds", "t", wire.format)
    ingest(cdr_payload(1, *statuses(("/a", "1.0"), ("/b", "2.0"), ("/c", "3.0"))))
    wire.decoded.clear()
    ingest(cdr_payload(2, *statuses(("/a", "1.05"), ("/b", "2.0"), ("/c", "3.0"))))
    # One byte longer: /b starts unaligned, so it decodes again (its padding differs); it ends where
    # the old one did, modulo 4, so /c is recognised.
    assert wire.decoded == ["/a", "/b"]
    wire.decoded.clear()
    ingest(cdr_payload(3, *statuses(("/a", "1.055555"), ("/b", "2.0"), ("/c", "3.0"))))
    assert wire.decoded == ["/a"]  # four bytes longer than the last: the rest sits aligned as before
    assert model.snapshot().robots[0].components[("/c", "")].values == (("voltage", "3.0"),)


def test_a_status_copied_byte_for_byte_to_an_unaligned_offset_is_decoded_not_recognised() -> None:
    sensor = DiagnosticStatus(1, "/sensor", "message!", "hw", (("key", "value"),))
    first = cdr_payload(1, DiagnosticStatus(0, "/a", "", "", (("k", "v"),)), sensor)
    grown = cdr_payload(2, DiagnosticStatus(0, "/a", "", "", (("k", "vv"),)), sensor)
    first_bounds = decode_laid_out(cdr.WIRE_FORMAT, first).bounds
    grown_bounds = decode_laid_out(cdr.WIRE_FORMAT, grown).bounds
    assert grown_bounds[1] - first_bounds[1] == 1
    # /sensor's bytes as they were, one byte later: read where they now sit, they are not /sensor.
    crafted = grown[: grown_bounds[1]] + first[first_bounds[1] :]
    with pytest.raises(DecodeError):
        decode_array(cdr.WIRE_FORMAT, crafted)
    model = FleetModel()
    ingest = PayloadIngest(model, "r1", "dds", "t", cdr.WIRE_FORMAT)
    ingest(first)
    with pytest.raises(DecodeError):
        ingest(crafted)


def test_a_robot_changed_by_another_topic_takes_the_next_payload_whole() -> None:
    model = FleetModel()
    agg = PayloadIngest(model, "r1", "dds", "rt/r1/diagnostics_agg", cdr.WIRE_FORMAT)
    raw = PayloadIngest(model, "r1", "dds", "rt/r1/diagnostics", cdr.WIRE_FORMAT)
    agg(cdr_payload(1, *statuses(("/a", "1.0"), ("/b", "2.0"))))
    raw(cdr_payload(1, *statuses(("/a", "9.0"), ("/b", "2.0"))))
    agg(cdr_payload(2, *statuses(("/a", "1.0"), ("/b", "2.5"))))
    components = model.snapshot().robots[0].components
    assert components[("/a", "")].values == (("voltage", "1.0"),)
    assert components[("/a", "")].feed == "rt/r1/diagnostics_agg"


def test_undecodable_payload_is_counted_and_the_next_good_one_applies() -> None:
    model = FleetModel()
    ingest = PayloadIngest(model, "r1", "dds", "t", cdr.WIRE_FORMAT)
    with pytest.raises(DecodeError):
        ingest(b"\x00\x01\x00\x00garbage")
    ingest(cdr_payload(1, DiagnosticStatus(1, "/a", "m", "")))
    snapshot = model.snapshot()
    assert snapshot.message_counts[("dds", "decode_error")] == 1
    assert snapshot.message_counts[("dds", "received")] == 1


def test_a_payload_cut_inside_a_changed_status_is_counted_and_applies_nothing() -> None:
    model = FleetModel()
    ingest = PayloadIngest(model, "r1", "dds", "t", cdr.WIRE_FORMAT)
    ingest(cdr_payload(1, *statuses(("/a", "1.0"), ("/b", "2.0"))))
    with pytest.raises(DecodeError):
        ingest(cdr_payload(2, *statuses(("/a", "1.0"), ("/b", "2.5")))[:-6])
    snapshot = model.snapshot()
    assert snapshot.message_counts[("dds", "decode_error")] == 1
    assert snapshot.robots[0].components[("/b", "")].values == (("voltage", "2.0"),)


def test_repeat_after_the_robot_was_forgotten_is_applied_again() -> None:
    clock = ManualClock()
    model = FleetModel(FleetLimits(expire_after=60), clock=clock)
    ingest = PayloadIngest(model, "r1", "dds", "t", cdr.WIRE_FORMAT)
    ingest(cdr_payload(1, DiagnosticStatus(0, "/a", "m", "")))
    clock.now += 61
    assert model.expire() == ["r1"]
    ingest(cdr_payload(2, DiagnosticStatus(0, "/a", "m", "")))
    assert [r.name for r in model.snapshot().robots] == ["r1"]


def test_components_forgotten_under_the_ingest_come_back_with_its_next_payload() -> None:
    model = FleetModel()
    ingest = PayloadIngest(model, "r1", "dds", "t", cdr.WIRE_FORMAT)
    ingest(cdr_payload(1, *statuses(("/a", "1.0"), ("/b", "2.0"))))
    model.forget_topic("r1", "t")
    ingest(cdr_payload(2, *statuses(("/a", "1.0"), ("/b", "2.0"))))  # republished
    assert set(model.snapshot().robots[0].components) == {("/a", ""), ("/b", "")}
    model.forget_topic("r1", "t")
    ingest(cdr_payload(3, *statuses(("/a", "1.0"), ("/b", "2.5"))))  # one status changed
    assert set(model.snapshot().robots[0].components) == {("/a", ""), ("/b", "")}


def test_a_republished_array_that_loses_statuses_counts_them_every_time() -> None:
    model = FleetModel()
    ingest = PayloadIngest(model, "r1", "dds", "t", cdr.WIRE_FORMAT)
    for stamp in (1, 2, 3):
        ingest(cdr_payload(stamp, DiagnosticStatus(0, "/a", "m", ""), DiagnosticStatus(9, "/b", "m", "")))
    snapshot = model.snapshot()
    assert snapshot.dropped_statuses["invalid_level"] == 3
    assert snapshot.message_counts[("dds", "dropped")] == 3


def test_ros1_republications_differ_only_in_seq_and_stamp() -> None:
    array = DiagnosticArray(1, 0, "", (DiagnosticStatus(1, "/a", "m", "", ()),))
    model = FleetModel()
    wire = CountingWire(ros1.WIRE_FORMAT)
    ingest = PayloadIngest(model, "r1", "ros1", "/diagnostics_agg", wire.format)
    for seq in range(3):
        ingest(ros1.encode_diagnostic_array(array._replace(stamp_sec=seq), seq))
    ingest(ros1.encode_diagnostic_array(array._replace(frame_id="map"), 3))
    assert wire.decoded == ["/a", "/a"]


def test_ros1_bytes_after_the_last_status_are_an_error_on_the_changed_path_too() -> None:
    model = FleetModel()
    ingest = PayloadIngest(model, "r1", "ros1", "/diagnostics_agg", ros1.WIRE_FORMAT)
    array = DiagnosticArray(1, 0, "", statuses(("/a", "1.0"), ("/b", "2.0")))
    ingest(ros1.encode_diagnostic_array(array))
    changed = array._replace(statuses=statuses(("/a", "1.0"), ("/b", "2.5")))
    with pytest.raises(DecodeError, match="left over"):
        ingest(ros1.encode_diagnostic_array(changed) + b"\x00")
    assert model.snapshot().message_counts[("ros1", "decode_error")] == 1


# Property: the ingest and the plain decode-and-apply path agree after any sequence of payloads.
# A small alphabet of names, levels and texts makes consecutive arrays share most of their statuses.
_texts = st.sampled_from(["", "ok", "a bit longer text", "x" * 40, "\u2603"])
_status = st.builds(
    DiagnosticStatus,
    level=st.sampled_from([0, 1, 2, 3, 7]),
    name=st.sampled_from(["/a", "/b", "/c", "/d", "/a/" + "n" * 30]),
    message=_texts,
    hardware_id=st.sampled_from(["", "hw"]),
    values=st.lists(st.tuples(st.sampled_from(["k", "voltage"]), _texts), max_size=3).map(tuple),
)
_arrays = st.lists(st.lists(_status, max_size=6).map(tuple), min_size=1, max_size=5)
_ENCODERS: dict[str, tuple[WireFormat, Callable[[DiagnosticArray], bytes]]] = {
    "cdr little endian": (cdr.WIRE_FORMAT, cdr.encode_diagnostic_array),
    "cdr big endian": (
        cdr.WIRE_FORMAT,
        lambda a: cdr.encode_diagnostic_array(a, little_endian=False),
    ),
    "ros1": (ros1.WIRE_FORMAT, ros1.encode_diagnostic_array),
}


def reference_decode(wire: WireFormat, payload: bytes) -> DiagnosticArray:
    """The whole payload decoded by the pure-Python codec, whichever decoder the ingest uses."""
    with codec_path("python"):
        return decode_array(wire, payload)


def _view(snapshot: FleetSnapshot) -> object:
    """What both paths must agree on: every record and judgement, but the revisions that count changes."""
    robots = [
        (
            r.name,
            r.last_message,
            dict(r.components),
            [feed._replace(revision=0) for feed in r.feeds],
            r.missing,
            r.up_since,
        )
        for r in snapshot.robots
    ]
    return robots, (
        dict(snapshot.message_counts),
        dict(snapshot.dropped_statuses),
        snapshot.truncated_strings,
    )


@pytest.mark.parametrize("encoding", sorted(_ENCODERS))
@settings(max_examples=examples(300), deadline=None)
@given(sequence=st.lists(st.tuples(_arrays, st.booleans()), min_size=1, max_size=4))
def test_ingest_agrees_with_decoding_and_applying_every_payload(
    encoding: str, sequence: list[tuple[list[tuple[DiagnosticStatus, ...]], bool]]
) -> None:
    wire, encode = _ENCODERS[encoding]
    clock = ManualClock()
    limits = FleetLimits(max_components_per_robot=4, max_values_per_component=2, max_string_length=20)
    fast = FleetModel(limits, clock=clock)
    plain = FleetModel(limits, clock=clock)
    ingest = PayloadIngest(fast, "r1", "dds", "t", wire)
    stamp = 0
    for arrays, forget in sequence:
        for items in arrays:
            stamp += 1
            clock.now += 1.0
            payload = encode(DiagnosticArray(stamp, stamp, "", items))
            ingest(payload)
            plain.apply("r1", reference_decode(wire, payload), "dds", "t")
            stamp += 1
            clock.now += 1.0
            ingest(encode(DiagnosticArray(stamp, stamp, "", items)))  # republished with a new stamp
            plain.apply("r1", reference_decode(wire, payload), "dds", "t")
        if forget:
            fast.forget_topic("r1", "t")
            plain.forget_topic("r1", "t")
        assert _view(fast.snapshot()) == _view(plain.snapshot())


def test_feeds_of_one_robot_keep_their_own_layouts_and_skip_their_own_republications() -> None:
    # Two nodes on one robot's topic, each republishing its own array: neither makes the other decode.
    model = FleetModel()
    wire = CountingWire(cdr.WIRE_FORMAT)
    drive = PayloadIngest(model, "r1", "dds", "rt/diagnostics", wire.format, "rt/diagnostics@drive")
    camera = PayloadIngest(model, "r1", "dds", "rt/diagnostics", wire.format, "rt/diagnostics@camera")
    for stamp in range(1, 6):
        drive(cdr_payload(stamp, *statuses(("drive: a", "1.0"), ("drive: b", "2.0"))))
        camera(cdr_payload(stamp, *statuses(("camera: c", "3.0"))))
    assert wire.decoded == ["drive: a", "drive: b", "camera: c"]
    drive(cdr_payload(6, *statuses(("drive: a", "1.0"), ("drive: b", "2.5"))))
    assert wire.decoded[3:] == ["drive: b"]
    robot = model.snapshot().robots[0]
    assert [feed.name for feed in robot.feeds] == ["rt/diagnostics@drive", "rt/diagnostics@camera"]
    assert robot.components[("drive: b", "")].values == (("voltage", "2.5"),) and not robot.missing
