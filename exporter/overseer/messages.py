"""The decoded form of diagnostic_msgs/DiagnosticArray, shared by every codec and the simulator."""

from __future__ import annotations

from typing import NamedTuple


class DiagnosticStatus(NamedTuple):
    """One diagnostic_msgs/DiagnosticStatus; `level` is the raw wire octet, `values` the key-value pairs."""

    level: int
    name: str
    message: str
    hardware_id: str
    values: tuple[tuple[str, str], ...] = ()


class DiagnosticArray(NamedTuple):
    """One diagnostic_msgs/DiagnosticArray with its header."""

    stamp_sec: int
    stamp_nanosec: int
    frame_id: str
    statuses: tuple[DiagnosticStatus, ...]
