"""Hashes of chosen fields of many records at once: what the exposition's cache keeps of a component.

`field_hashes(records, fields)` (one field at least) is, for each record,
`hash(tuple(record[f] for f in fields))` as a native 64-bit integer, all of them one after another in
bytes (`array("q").frombytes` reads them). The work is done by `_cstamps` (C) where it was built,
without building a tuple a record; without it, by `map` and `zip`, with the same numbers.
"""

from __future__ import annotations

from array import array
from collections.abc import Callable
from operator import itemgetter

try:
    from overseer.fleet import _cstamps
except ImportError:  # installed without a C compiler
    _cstamps = None  # type: ignore[assignment]


def field_hashes_in_python(records: tuple[tuple[object, ...], ...], fields: bytes) -> bytes:
    """`_cstamps.field_hashes` by Python: the fields picked by `map`, their tuples made by `zip`."""
    if not fields:
        raise ValueError("field_hashes: no fields")
    picked = [map(itemgetter(field), records) for field in fields]
    return array("q", map(hash, zip(*picked, strict=True))).tobytes()


COMPILED = _cstamps is not None
field_hashes: Callable[[tuple[tuple[object, ...], ...], bytes], bytes] = (
    _cstamps.field_hashes if COMPILED else field_hashes_in_python
)
