"""The maintenance families in `/metrics`: a line for every robot, rendered again only when one changes.

# HELP ros_diagnostics_robot_maintenance 1 while the robot is in a maintenance window, else 0.
# TYPE ros_diagnostics_robot_maintenance gauge
ros_diagnostics_robot_maintenance{robot="robot3"} 1.0

Every robot the fleet names has a line at every scrape, in or out of a window. prometheus-client made
those 10,000 lines at 10,000 robots in 34 ms a scrape; here they are written as the exposition formats
write them (the same bytes) and kept, with their deflated piece, until a robot comes or goes, a window
starts, ends or moves its end, or the windows' counts move.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from typing import NamedTuple

from overseer.fleet import metric_families as contract
from overseer.fleet.deflated import Deflated, deflate
from overseer.fleet.exposition import escape_label_value, go_float
from overseer.maintenance.schedule import MaintenanceSchedule
from overseer.serve.exposition_formats import ExpositionFormat


class _State(NamedTuple):
    """What the lines say: robots by name, the end of each one's window (robots in one), the counts."""

    robots: tuple[str, ...]
    ends: tuple[tuple[str, float], ...]
    active: int
    scheduled: int


class _Rendered(NamedTuple):
    """A state's lines in one format, and their deflated piece once a gzip answer needed it."""

    state: _State
    text: bytes
    deflated: Deflated | None


class MaintenanceLines:
    """The maintenance state of every robot `robots()` names (the fleet's), and the windows counted.

    Scrapes at once may each render a state: each answers whole lines of one state, and at worst one
    replaces the other's newer lines with its own, rendered again at the next scrape.
    """

    def __init__(self, schedule: MaintenanceSchedule, robots: Callable[[], Iterable[str]]) -> None:
        """Judge `robots()` (the fleet's robot names now) against `schedule`'s windows at each scrape."""
        self._schedule = schedule
        self._robots = robots
        self._last_answer: tuple[list[str], tuple[str, ...]] = ([], ())  # the fleet's names, and sorted
        self._rendered: dict[bool, _Rendered] = {}  # by format: OpenMetrics or not

    def text(self, fmt: ExpositionFormat) -> bytes:
        """The families' lines in `fmt`, headers included."""
        return self._current(fmt).text

    def deflated(self, fmt: ExpositionFormat) -> Deflated:
        """`text(fmt)` as a deflated piece of a gzip answer."""
        rendered = self._current(fmt)
        if rendered.deflated is not None:
            return rendered.deflated
        piece = deflate(rendered.text)
        if self._rendered.get(fmt.openmetrics) is rendered:
            self._rendered[fmt.openmetrics] = rendered._replace(deflated=piece)
        return piece

    def _current(self, fmt: ExpositionFormat) -> _Rendered:
        state = self._state()
        rendered = self._rendered.get(fmt.openmetrics)
        if rendered is None or rendered.state != state:
            rendered = self._rendered[fmt.openmetrics] = _Rendered(state, _render(state, fmt), None)
        return rendered

    def _state(self) -> _State:
        now = self._schedule.clock()
        windows = self._schedule.windows(now)
        active = [window for window in windows if window.active(now)]
        robots = self._sorted_names()
        ends: list[tuple[str, float]] = []
        if active:
            for robot in robots:
                state = self._schedule.state(robot, active)
                if state is not None:
                    ends.append((robot, state.until))
        scheduled = sum(1 for window in windows if window.start > now)
        return _State(robots, tuple(ends), len(active), scheduled)

    def _sorted_names(self) -> tuple[str, ...]:
        """The fleet's names, sorted once for as long as the fleet answers the same list."""
        names = list(self._robots())
        last, ordered = self._last_answer
        if names != last:
            ordered = tuple(sorted(set(names)))
            self._last_answer = (names, ordered)
        return ordered


def _render(state: _State, fmt: ExpositionFormat) -> bytes:
    """`state` as prometheus-client writes these families, in `fmt`."""
    in_window = {robot for robot, _ in state.ends}
    lines = [fmt.header(contract.MAINTENANCE)]
    for robot in state.robots:
        flag = "1.0" if robot in in_window else "0.0"
        lines.append(f'ros_diagnostics_robot_maintenance{{robot="{escape_label_value(robot)}"}} {flag}\n')
    lines.append(fmt.header(contract.MAINTENANCE_END))
    for robot, until in state.ends:
        lines.append(
            "ros_diagnostics_robot_maintenance_end_timestamp_seconds"
            f'{{robot="{escape_label_value(robot)}"}} {go_float(until)}\n'
        )
    lines.append(fmt.header(contract.MAINTENANCE_WINDOWS))
    lines.append(f'overseer_maintenance_windows{{state="active"}} {go_float(float(state.active))}\n')
    lines.append(f'overseer_maintenance_windows{{state="scheduled"}} {go_float(float(state.scheduled))}\n')
    return "".join(lines).encode()
