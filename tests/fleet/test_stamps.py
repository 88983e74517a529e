"""The exposition's field hashes: the compiled ones and the fallback give Python's own tuple hashes."""

from __future__ import annotations

import importlib
from array import array

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from overseer.fleet import exposition, stamps
from overseer.levels import Level
from overseer.model.state import Component
from support.examples import examples

IMPLEMENTATIONS = {"python": stamps.field_hashes_in_python}
if stamps.COMPILED:
    IMPLEMENTATIONS["compiled"] = importlib.import_module("overseer.fleet._cstamps").field_hashes


def test_the_compiled_field_hashes_were_built() -> None:
    assert stamps.COMPILED, "the compiled field hashes were not built (make setup builds them)"
    assert stamps.field_hashes is IMPLEMENTATIONS["compiled"]


def reference(records: tuple[tuple[object, ...], ...], fields: bytes) -> list[int]:
    """What the hashes must be: Python's hash of a tuple of the fields."""
    return [hash(tuple(record[field] for field in fields)) for record in records]


_texts = st.text(max_size=8) | st.sampled_from(["", "\ud800", "☃"])
_fields = st.one_of(
    _texts, st.integers(-(2**70), 2**70), st.sampled_from(list(Level)), st.floats(allow_nan=False)
)
_records = st.lists(st.tuples(_fields, _fields, _fields, _fields), max_size=30).map(tuple)


@settings(max_examples=examples(200), deadline=None)
@given(records=_records, fields=st.lists(st.integers(0, 3), min_size=1, max_size=6).map(bytes))
@pytest.mark.parametrize("name", ["python", "compiled"])
def test_field_hashes_are_pythons_hashes_of_the_fields_tuple(
    name: str, records: tuple[tuple[object, ...], ...], fields: bytes
) -> None:
    field_hashes = IMPLEMENTATIONS[name]
    hashes = array("q")
    hashes.frombytes(field_hashes(records, fields))
    assert hashes.tolist() == reference(records, fields)


@pytest.mark.parametrize("name", ["python", "compiled"])
def test_a_components_stamps_are_the_hashes_of_its_fields(name: str, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(exposition, "field_hashes", IMPLEMENTATIONS[name])
    records = [
        Component(("/a", ""), Level.WARN, "warm", "hw1", (("v", "1.5"),), 1.0, 3, "f"),
        Component(("/b", "x"), Level.OK, "ok", "", (), 2.0, 0, "f"),
    ]
    components = {record.key: record for record in records}
    assert exposition._stamps(components, frozenset({("/b", "x")})).tolist() == [
        hash((("/a", ""), Level.WARN, "warm", "hw1", 3)),
        -1,  # missing from its feed's latest message: never copied
        hash(((("v", "1.5"),),)),
        hash(((),)),
    ]


@pytest.mark.parametrize("name", ["python", "compiled"])
@pytest.mark.parametrize(
    ("records", "fields", "error"),
    [
        (((1, 2),), b"", ValueError),
        (((1, 2),), b"\x02", IndexError),
        (((1, [2]),), b"\x01", TypeError),  # an unhashable field
    ],
    ids=["no fields", "a field beyond the record", "an unhashable field"],
)
def test_field_hashes_refuse_what_cannot_be_hashed(
    name: str, records: tuple[tuple[object, ...], ...], fields: bytes, error: type[Exception]
) -> None:
    with pytest.raises(error):
        IMPLEMENTATIONS[name](records, fields)


def test_the_compiled_field_hashes_take_tuples_alone() -> None:
    # Records in a tuple, and each a tuple: nothing an item's hash runs can take one away meanwhile.
    compiled = IMPLEMENTATIONS["compiled"]
    with pytest.raises(TypeError, match="record 1 is not a tuple"):
        compiled(((1, 2), [1, 2]), b"\x00")  # type: ignore[arg-type]
    with pytest.raises(TypeError):
        compiled([(1, 2)], b"\x00")  # type: ignore[arg-type]
