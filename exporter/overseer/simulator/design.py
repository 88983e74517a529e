"""The virtual robots' diagnostics, as the paper's simulator and a ROS diagnostic aggregator produce them.

Pure data: which components a simulated robot has, their levels, messages and key-values. The
simulator publishes what this module builds, and tests use it to know what to expect.
"""

from __future__ import annotations

from dataclasses import dataclass

from overseer.levels import Level
from overseer.messages import DiagnosticStatus

GROUPS = ("Power", "Motor", "Temp", "Laser", "Camera")

_MESSAGES = {
    "Power": ("Charge OK", "Low charge", "Battery critical"),
    "Motor": ("Running", "High current", "Motor fault"),
    "Temp": ("Normal", "High temperature", "Overheating"),
    "Laser": ("Scanning", "Low scan rate", "No scans received"),
    "Camera": ("Streaming", "Frame drops", "No frames received"),
}
_GROUP_MESSAGES = {Level.OK: "OK", Level.WARN: "Warning", Level.ERROR: "Error", Level.STALE: "Stale"}


@dataclass(frozen=True)
class LeafComponent:
    """A simulated sensor or actuator: its group, full name and hardware id."""

    group: str
    number: int
    name: str
    hardware_id: str


def leaf_components(count: int) -> list[LeafComponent]:
    """The first `count` leaves, round-robin over the groups (Power, Motor, Temp, Laser, Camera)."""
    leaves = []
    for index in range(count):
        group = GROUPS[index % len(GROUPS)]
        number = index // len(GROUPS) + 1
        leaves.append(
            LeafComponent(group, number, f"/{group}/{_leaf_name(group, number)}", f"{group.lower()}{number}")
        )
    return leaves


def initial_levels(leaves: list[LeafComponent], warn: int, error: int) -> dict[str, Level]:
    """Level per leaf name: the last `warn` leaves WARN, the `error` before them ERROR, the rest OK."""
    levels = {leaf.name: Level.OK for leaf in leaves}
    ordered = [leaf.name for leaf in leaves]
    warn_names = ordered[len(ordered) - warn :] if warn else []
    error_names = ordered[max(0, len(ordered) - warn - error) : len(ordered) - warn] if error else []
    for name in warn_names:
        levels[name] = Level.WARN
    for name in error_names:
        levels[name] = Level.ERROR
    return levels


def leaf_status(leaf: LeafComponent, level: Level) -> DiagnosticStatus:
    """The status a leaf publishes at `level`, with plausible numeric key-values."""
    severity = min(int(level), 2)
    message = "Stale" if level is Level.STALE else _MESSAGES[leaf.group][severity]
    return DiagnosticStatus(int(level), leaf.name, message, leaf.hardware_id, _leaf_values(leaf, severity))


def aggregated_statuses(
    leaves: list[LeafComponent], levels: dict[str, Level], silenced: set[str]
) -> list[DiagnosticStatus]:
    """A robot's /diagnostics_agg content: group statuses (max level of their children) and leaves."""
    statuses = []
    group_levels: dict[str, int] = {}
    for leaf in leaves:
        if leaf.name in silenced:
            continue
        level = levels[leaf.name]
        statuses.append(leaf_status(leaf, level))
        group_levels[leaf.group] = max(group_levels.get(leaf.group, 0), int(level))
    for group, level_value in group_levels.items():
        statuses.append(DiagnosticStatus(level_value, f"/{group}", _GROUP_MESSAGES[Level(level_value)], ""))
    statuses.sort(key=lambda status: status.name)
    return statuses


def _leaf_name(group: str, number: int) -> str:
    if group == "Power":
        return {1: "Robot Battery", 2: "Laptop Battery"}.get(number, f"Battery{number}")
    prefix = {"Motor": "Motor", "Temp": "Sensor", "Laser": "Laser", "Camera": "Cam"}[group]
    return f"{prefix}{number}"


def _leaf_values(leaf: LeafComponent, severity: int) -> tuple[tuple[str, str], ...]:
    if leaf.group == "Power":
        percentage = (85.0, 18.0, 4.0)[severity]
        return (("voltage", f"{11.0 + percentage / 50:.2f}"), ("percentage", f"{percentage:.1f}"))
    if leaf.group == "Motor":
        return (
            ("temperature", f"{(45.0, 72.0, 95.0)[severity]:.1f}"),
            ("current", f"{(1.2, 4.8, 0.0)[severity]:.2f}"),
        )
    if leaf.group == "Temp":
        return (("temperature", f"{(38.0 + leaf.number, 71.0, 96.0)[severity]:.1f}"),)
    if leaf.group == "Laser":
        return (("frequency", f"{(40.0, 12.0, 0.0)[severity]:.1f}"),)
    return (("fps", f"{(30.0, 11.0, 0.0)[severity]:.1f}"),)
