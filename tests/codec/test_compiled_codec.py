"""The compiled status decoder against the pure-Python one: built and used, same answers, same errors.

Differential fuzzing: random and damaged payloads must give the compiled decoder (`_cstatus.c`) and the
pure-Python reference the same statuses, or both a DecodeError with the same message, and the same for
the ingest's status-by-status comparison (`scan_changed`). The subprocess tests prove the normal install
uses the compiled decoder, that `OVERSEER_PURE_PYTHON=1` turns it off, and that the package still works,
in pure Python, when the extension is missing.
"""

from __future__ import annotations

import os
import struct
import subprocess
import sys
from array import array
from collections.abc import Callable
from itertools import chain, pairwise
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from overseer.codec import DecodeError, cdr, compiled, ros1
from overseer.codec.wire import StatusReader, WireFormat, decode_array, decode_laid_out
from overseer.ingest.scan import scan_python
from overseer.messages import DiagnosticArray, DiagnosticStatus
from overseer.model import FleetLimits
from overseer.model.fleet import _intact
from support import strategies
from support.codec_paths import codec_path
from support.examples import examples
from support.strategies import damaged
from testbed.processes import running_exporter, wait_for

FUZZ = settings(max_examples=examples(1000), deadline=None, suppress_health_check=[HealthCheck.too_slow])

# name → (wire format, encoder, pure-Python reader, compiled reader's name)
Encoder = Callable[[DiagnosticArray], bytes]
LAYOUTS: dict[str, tuple[WireFormat, Encoder, StatusReader, str]] = {
    "cdr little endian": (cdr.WIRE_FORMAT, cdr.encode_diagnostic_array, cdr._READ_STATUS_LE, "cdr_le"),
    "cdr big endian": (
        cdr.WIRE_FORMAT,
        lambda a: cdr.encode_diagnostic_array(a, little_endian=False),
        cdr._READ_STATUS_BE,
        "cdr_be",
    ),
    "ros1": (ros1.WIRE_FORMAT, ros1.encode_diagnostic_array, ros1.read_status, "ros1"),
}
layout_names = st.sampled_from(sorted(LAYOUTS))
arrays = strategies.arrays(st.integers(min_value=0, max_value=2**31 - 1))


def outcome(call: Callable[[], object]) -> object:
    """What a call gives: its result, or the DecodeError's message."""
    try:
        return call()
    except DecodeError as error:
        return ("DecodeError", str(error))


@st.composite
def payloads(draw: st.DrawFn, name: str) -> bytes:
    """A valid payload of layout `name`, often damaged, sometimes random bytes behind a valid header."""
    encode = LAYOUTS[name][1]
    valid = encode(draw(arrays))
    kind = draw(st.sampled_from(["valid", "damaged", "damaged", "random"]))
    if kind == "valid":
        return valid
    if kind == "damaged":
        return draw(damaged(valid))
    return valid[:16] + draw(st.binary(max_size=256))


def test_the_normal_install_built_and_uses_the_compiled_decoder() -> None:
    script = (
        "from overseer.codec import cdr, compiled, ros1\n"
        "head = cdr.read_head(cdr.encode_diagnostic_array(cdr.DiagnosticArray(0, 0, '', ())))\n"
        "uses = head.read_status is compiled.READERS['cdr_le']\n"
        "print(compiled.AVAILABLE, compiled.implementation(), uses)\n"
    )
    env = {k: v for k, v in os.environ.items() if k != compiled.PURE_PYTHON_VARIABLE}
    result = subprocess.run(
        [sys.executable, "-c", script], env=env, capture_output=True, text=True, check=True
    )
    assert result.stdout.split() == ["True", "compiled", "True"]


def test_overseer_pure_python_turns_the_compiled_decoder_off() -> None:
    script = "from overseer.codec import compiled\nprint(compiled.AVAILABLE, compiled.implementation())\n"
    env = {**os.environ, compiled.PURE_PYTHON_VARIABLE: "1"}
    result = subprocess.run(
        [sys.executable, "-c", script], env=env, capture_output=True, text=True, check=True
    )
    assert result.stdout.split() == ["True", "python"]


def test_without_the_extension_everything_decodes_in_pure_python() -> None:
    # None in sys.modules makes the import fail, as on a machine that had no C compiler.
    script = """
import sys
sys.modules["overseer.codec._cstatus"] = None
from overseer.codec import DecodeError, cdr, compiled
from overseer.messages import DiagnosticArray, DiagnosticStatus
from overseer.model import FleetLimits
from overseer.model.fleet import _intact
from overseer.model import FleetModel
from overseer.ingest.payload import PayloadIngest
array = DiagnosticArray(1, 2, "f", (DiagnosticStatus(1, "/a", "m", "hw", (("k", "v"),)),))
model = FleetModel()
ingest = PayloadIngest(model, "r1", "dds", "t", cdr.WIRE_FORMAT)
ingest(cdr.encode_diagnostic_array(array))
ingest(cdr.encode_diagnostic_array(array._replace(statuses=(array.statuses[0]._replace(level=2),))))
try:
    compiled.use_compiled(True)
except RuntimeError as error:
    refused = "not built" in str(error)
level = model.snapshot().robots[0].components[("/a", "")].level
print(compiled.AVAILABLE, compiled.implementation(), refused, int(level), "not built" in compiled.describe())
"""
    env = {k: v for k, v in os.environ.items() if k != compiled.PURE_PYTHON_VARIABLE}
    result = subprocess.run(
        [sys.executable, "-c", script], env=env, capture_output=True, text=True, check=True
    )
    assert result.stdout.split() == ["False", "python", "True", "2", "True"]


@pytest.mark.servers
@pytest.mark.parametrize("pure_python", [False, True], ids=["compiled", "pure-python"])
def test_the_exporter_logs_and_exports_which_decoder_it_runs(
    tmp_path: Path, dds_domain: int, monkeypatch: pytest.MonkeyPatch, pure_python: bool
) -> None:
    monkeypatch.setenv(compiled.PURE_PYTHON_VARIABLE, "1" if pure_python else "0")
    codec = "python" if pure_python else "compiled"
    with running_exporter(tmp_path, dds_domain) as exporter:
        build_info = {dict(labels)["codec"] for labels in exporter.samples()["overseer_build_info"]}
        assert build_info == {codec}
        line = f"status decoder: {'pure Python' if pure_python else 'compiled'}"
        wait_for(lambda: line in exporter.log(), timeout=10, message=line)


@pytest.mark.parametrize("name", sorted(LAYOUTS))
def test_each_layout_hands_out_its_own_reader(name: str) -> None:
    wire, encode, pure, compiled_name = LAYOUTS[name]
    payload = encode(DiagnosticArray(0, 0, "", (DiagnosticStatus(0, "/a", "", ""),)))
    with codec_path("compiled"):
        assert wire.read_head(payload).read_status is compiled.READERS[compiled_name]
    with codec_path("python"):
        assert wire.read_head(payload).read_status is pure


@FUZZ
@given(st.data(), layout_names)
def test_whole_payloads_decode_alike_or_fail_alike(data: st.DataObject, name: str) -> None:
    wire = LAYOUTS[name][0]
    payload = data.draw(payloads(name))
    with codec_path("python"):
        expected = outcome(lambda: decode_laid_out(wire, payload)[:2])
    with codec_path("compiled"):
        assert outcome(lambda: decode_laid_out(wire, payload)[:2]) == expected


@FUZZ
@given(st.binary(max_size=300), st.integers(min_value=0, max_value=300), st.integers(0, 300), layout_names)
def test_a_status_read_anywhere_in_random_bytes_reads_alike(
    data: bytes, pos: int, end: int, name: str
) -> None:
    _, _, pure, compiled_name = LAYOUTS[name]
    end = min(end, len(data))
    expected = outcome(lambda: pure(data, pos, end))
    assert outcome(lambda: compiled.READERS[compiled_name](data, pos, end)) == expected


@FUZZ
@given(st.data(), layout_names, st.integers(0, 30), st.integers(0, 4))
def test_the_changed_statuses_scan_alike(
    data: st.DataObject, name: str, max_length: int, max_values: int
) -> None:
    wire, encode, _, compiled_name = LAYOUTS[name]
    first = encode(data.draw(arrays))
    laid_out = decode_laid_out(wire, first)
    hashes = array("q", [hash(first[a:b]) for a, b in pairwise(laid_out.bounds)])
    # The next payload: another array (often sharing statuses with the first), or the first damaged.
    damage = data.draw(st.booleans())
    second = data.draw(
        damaged(first)
        if damage
        else st.one_of(
            st.just(first),
            arrays.map(encode),
            st.lists(st.sampled_from(laid_out.decoded.statuses or (DiagnosticStatus(0, "", "", ""),))).map(
                lambda items: encode(laid_out.decoded._replace(statuses=tuple(items)))
            ),
        )
    )
    misaligned = wire.alignment - 1
    layout = compiled.LAYOUTS[compiled.READERS[compiled_name]]
    limits = FleetLimits(max_string_length=max_length, max_values_per_component=max_values)

    def scan(in_c: bool, max_length: int = max_length, max_values: int = max_values) -> tuple[object, ...]:
        bounds, scanned_hashes = array("I", laid_out.bounds), array("q", hashes)
        args = (second, bounds[0], len(second), bounds, scanned_hashes, misaligned)
        if in_c:
            found = outcome(lambda: compiled.scan_changed(layout, *args, max_length, max_values))
        else:
            found = outcome(lambda: scan_python(LAYOUTS[name][2], *args))
        return found, bounds.tolist(), scanned_hashes.tolist()

    (found, *in_c), (expected, *in_python) = scan(in_c=True), scan(in_c=False)
    assert in_c == in_python
    if not isinstance(expected, tuple) or expected[0] == "DecodeError":
        assert found == expected
        return
    assert isinstance(found, tuple)
    changed, pos, fits = found
    assert (changed, pos) == expected
    if fits:  # what the model is then spared checking, it would have found so
        assert _intact(changed, limits)
    if changed and not damage:
        # Valid UTF-8, so a text's bytes are its encoding: the report is exact, at the limits' edges too.
        texts = [t for _, s in changed for t in (s.name, s.message, s.hardware_id, *chain(*s.values))]
        longest = max(len(text.encode()) for text in texts)
        most = max(len(status.values) for _, status in changed)
        valid = all(status.level <= 3 for _, status in changed)
        for length, values in ((longest, most), (longest - 1, most), (longest, most - 1)):
            reported = scan(in_c=True, max_length=length, max_values=values)[0]
            assert isinstance(reported, tuple)
            assert reported[2] == (valid and length == longest and values == most)


@pytest.mark.parametrize("name", sorted(LAYOUTS))
def test_a_status_that_changed_is_found_and_rehashed_as_python_hashes_it(name: str) -> None:
    wire, encode, _, compiled_name = LAYOUTS[name]
    items = tuple(DiagnosticStatus(0, f"/{n}", "ok", "", (("v", "1.0"),)) for n in "abc")
    first = encode(DiagnosticArray(1, 0, "", items))
    second = encode(
        DiagnosticArray(2, 0, "", (items[0], items[1]._replace(level=2, message="bad"), items[2]))
    )
    bounds = decode_laid_out(wire, first).bounds
    hashes = array("q", [hash(first[a:b]) for a, b in pairwise(bounds)])
    layout = compiled.LAYOUTS[compiled.READERS[compiled_name]]
    changed, pos, fits = compiled.scan_changed(
        layout, second, bounds[0], len(second), bounds, hashes, wire.alignment - 1, 3, 1
    )
    assert changed == [(1, items[1]._replace(level=2, message="bad"))]
    assert fits  # "bad" is three bytes, one key-value
    assert pos == len(second) or name != "ros1"
    assert list(bounds) == list(decode_laid_out(wire, second).bounds)
    assert list(hashes) == [hash(second[a:b]) for a, b in pairwise(bounds)]


def test_bad_arguments_are_refused_not_read() -> None:
    payload = cdr.encode_diagnostic_array(DiagnosticArray(0, 0, "", (DiagnosticStatus(0, "/a", "", ""),)))
    read = compiled.READERS["cdr_le"]
    layout = compiled.LAYOUTS[read]
    with pytest.raises(ValueError, match="outside"):
        read(payload, 0, len(payload) + 1)
    with pytest.raises(ValueError, match="outside"):
        read(payload, -1, len(payload))
    end = len(payload)
    with pytest.raises(TypeError, match="array"):
        compiled.scan_changed(layout, payload, 20, end, array("i", [20, 40]), array("q", [0]), 3, 9, 9)
    with pytest.raises(TypeError, match="array"):
        wrong = array("d", [0.0])
        compiled.scan_changed(layout, payload, 20, end, array("I", [20, 40]), wrong, 3, 9, 9)  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="one more"):
        compiled.scan_changed(layout, payload, 20, end, array("I", [20]), array("q", [0]), 3, 9, 9)
    with pytest.raises(ValueError, match="at least one"):
        compiled.read_statuses(layout, payload, 20, len(payload), array("I"))
    with pytest.raises(ValueError, match="unknown layout"):
        compiled.read_statuses(99, payload, 20, len(payload), array("I", [0, 0]))


def test_a_lying_value_count_is_refused_before_allocating() -> None:
    status = DiagnosticStatus(0, "/a", "", "", (("k", "v"),))
    payload = bytearray(cdr.encode_diagnostic_array(DiagnosticArray(0, 0, "", (status,))))
    count_at = payload.index(struct.pack("<II", 1, 2) + b"k\x00")  # the values count, then the key "k"
    struct.pack_into("<I", payload, count_at, 0xFFFFFFFF)
    with codec_path("compiled"), pytest.raises(DecodeError, match="value count 4294967295 runs past"):
        decode_array(cdr.WIRE_FORMAT, bytes(payload))
