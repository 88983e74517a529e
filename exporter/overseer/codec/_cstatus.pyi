"""Types of the compiled status decoder (`_cstatus.c`)."""

from array import array

from overseer.messages import DiagnosticStatus

CDR_LE: int
CDR_BE: int
ROS1: int
SHARED_PAIRS_LIMIT: int
SHARED_VALUES_LIMIT: int
SHARED_TEXT: int
SHARED_PAIRS: int

def setup(status_type: type[DiagnosticStatus], decode_error: type[Exception], /) -> None: ...
def read_status_cdr_le(payload: bytes, pos: int, end: int, /) -> tuple[DiagnosticStatus, int]: ...
def read_status_cdr_be(payload: bytes, pos: int, end: int, /) -> tuple[DiagnosticStatus, int]: ...
def read_status_ros1(payload: bytes, pos: int, end: int, /) -> tuple[DiagnosticStatus, int]: ...
def read_statuses(
    layout: int, payload: bytes, pos: int, end: int, bounds: array[int], /
) -> tuple[DiagnosticStatus, ...]: ...
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
    /,
) -> tuple[list[tuple[int, DiagnosticStatus]], int, bool]: ...
def shared_reset() -> None: ...
def shared_sizes() -> tuple[int, int]: ...
