"""The compiled status decoder (`_cstatus.c`) when it was built, and the switch back to pure Python.

The C decoder reads statuses exactly as the pure-Python readers of `cdr.py` and `ros1.py` do, into the
same named tuples with the same `DecodeError`s; those readers stay the reference and the fallback. It is
used when the package was installed with a C compiler at hand, unless `OVERSEER_PURE_PYTHON=1` is in the
environment. `use_compiled` switches at run time (the tests run the codec tests on both paths).

Unlike them, it keeps one copy of the small key-value pairs and values tuples that statuses repeat
(robots of one fleet report the same ones), up to `SHARED_PAIRS_LIMIT` and `SHARED_VALUES_LIMIT` of them,
and for a while looks up none of a key or a status whose values rarely repeat: the statuses are equal
either way, and a fleet's model holds fewer objects.
"""

from __future__ import annotations

import os
from array import array
from collections.abc import Callable

from overseer.codec.errors import DecodeError
from overseer.messages import DiagnosticStatus

try:
    from overseer.codec import _cstatus
except ImportError:  # installed without a C compiler: pure Python only
    _cstatus = None  # type: ignore[assignment]
else:
    _cstatus.setup(DiagnosticStatus, DecodeError)

StatusReader = Callable[[bytes, int, int], tuple[DiagnosticStatus, int]]

AVAILABLE = _cstatus is not None
SHARED_PAIRS_LIMIT = _cstatus.SHARED_PAIRS_LIMIT if AVAILABLE else 0
SHARED_VALUES_LIMIT = _cstatus.SHARED_VALUES_LIMIT if AVAILABLE else 0
SHARED_TEXT = _cstatus.SHARED_TEXT if AVAILABLE else 0  # bytes of a pair's key and value, at most
SHARED_PAIRS = _cstatus.SHARED_PAIRS if AVAILABLE else 0  # pairs of a values tuple shared, at most
PURE_PYTHON_VARIABLE = "OVERSEER_PURE_PYTHON"

# Read by the codecs for every payload: whether they hand out the compiled readers.
enabled = AVAILABLE and os.environ.get(PURE_PYTHON_VARIABLE, "") not in ("1", "true", "yes")

# The compiled readers by layout ("cdr_le", "cdr_be", "ros1"), and each one's code for the bulk
# functions `_cstatus.read_statuses` and `_cstatus.scan_changed`.
READERS: dict[str, StatusReader] = (
    {
        "cdr_le": _cstatus.read_status_cdr_le,
        "cdr_be": _cstatus.read_status_cdr_be,
        "ros1": _cstatus.read_status_ros1,
    }
    if AVAILABLE
    else {}
)
LAYOUTS: dict[StatusReader, int] = (
    {READERS["cdr_le"]: _cstatus.CDR_LE, READERS["cdr_be"]: _cstatus.CDR_BE, READERS["ros1"]: _cstatus.ROS1}
    if AVAILABLE
    else {}
)


def use_compiled(on: bool) -> bool:
    """Make the codecs use the compiled decoder (True) or pure Python (False); returns the previous choice."""
    global enabled
    if on and not AVAILABLE:
        raise RuntimeError("the compiled decoder overseer.codec._cstatus was not built")
    previous, enabled = enabled, on
    return previous


def describe() -> str:
    """One line for the log at start: which decoder runs, and why when it is the slower one."""
    if enabled:
        return "status decoder: compiled"
    if AVAILABLE:
        return f"status decoder: pure Python ({PURE_PYTHON_VARIABLE} is set)"
    return (
        "status decoder: pure Python, the compiled one was not built (no C compiler at install); "
        "arrays that change in every status decode about 3 times slower"
    )


def implementation() -> str:
    """Which decoder the codecs use now: "compiled" or "python"."""
    return "compiled" if enabled else "python"


def read_statuses(
    layout: int, payload: bytes, pos: int, end: int, bounds: array[int]
) -> tuple[DiagnosticStatus, ...]:
    """len(bounds) - 1 statuses from `pos`, filling `bounds` with where each began and the last ended."""
    return _cstatus.read_statuses(layout, payload, pos, end, bounds)


def scan_changed(
    layout: int,
    payload: bytes,
    pos: int,
    end: int,
    bounds: array[int],
    hashes: array[int],
    misaligned: int,
    max_length: int,
    max_values: int,
) -> tuple[list[tuple[int, DiagnosticStatus]], int, bool]:
    """The statuses that changed since the last payload, where the last one ended, and whether they fit.

    The ingest's status-by-status comparison (`PayloadIngest`), in C; `bounds` and `hashes` change in
    place. They fit when every one has a level of 0 to 3, no text longer than `max_length` bytes and
    at most `max_values` key-values: then the fleet model's limits would cut nothing of them.
    """
    return _cstatus.scan_changed(
        layout, payload, pos, end, bounds, hashes, misaligned, max_length, max_values
    )


def forget_shared() -> None:
    """Make the compiled decoder forget the key-values it keeps to share, and how often they repeated."""
    _cstatus.shared_reset()


def shared_sizes() -> tuple[int, int]:
    """How many key-value pairs and values tuples the compiled decoder keeps to share between statuses."""
    return _cstatus.shared_sizes()
