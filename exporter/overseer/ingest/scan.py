"""The status-by-status comparison of a payload with the last one: which statuses changed, decoded.

Two implementations side by side, with the same hashes and results: `scan_python`, the reference, and
`scan_compiled`, the same loop in C (in `codec/_cstatus.c`, beside the decoder it calls), which also
tells whether the changed statuses fit the model's limits. `tests/codec/test_compiled_codec.py` holds
them equal.
"""

from __future__ import annotations

from array import array

from overseer.codec import compiled
from overseer.codec.wire import StatusReader
from overseer.messages import DiagnosticStatus

scan_compiled = compiled.scan_changed


def scan_python(
    read_status: StatusReader,
    payload: bytes,
    pos: int,
    end: int,
    bounds: array[int],
    hashes: array[int],
    misaligned: int,
) -> tuple[list[tuple[int, DiagnosticStatus]], int]:
    """The statuses that changed since the last payload, and where the last status ended.

    A status whose bytes hash as they did, at an offset that keeps the alignment, is skipped; any other
    is decoded and its bound and hash updated in place. `scan_compiled` does the same in C.
    """
    changed: list[tuple[int, DiagnosticStatus]] = []
    shift = 0  # how much later than in the last payload the statuses now sit
    for index, old_hash in enumerate(hashes):
        after = bounds[index + 1] + shift
        if shift & misaligned or hash(payload[pos:after]) != old_hash:
            status, after = read_status(payload, pos, end)
            changed.append((index, status))
            hashes[index] = hash(payload[pos:after])
            shift = after - bounds[index + 1]
            bounds[index + 1] = after
        elif shift:
            bounds[index + 1] = after
        pos = after
    return changed, pos
