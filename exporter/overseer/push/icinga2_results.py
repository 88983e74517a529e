"""What to tell Icinga 2 about one robot: its host's state and each service's check result.

Each service's result is exactly what `check_ros_diagnostics` prints for the robot (and, for a group
service, for `--name-regex '^/<Group>(/|$)'`): the same verdict (`overseer.verdict`), judged from the
snapshot the API document is made of, its parts handed to Icinga as they are (text and perfdata items).
"""

from __future__ import annotations

import re
from dataclasses import dataclass

from overseer.model import FleetSnapshot, RobotState
from overseer.push.icinga2_names import (
    ROBOT_SERVICE,
    group_of,
    group_pattern,
    group_service_name,
    host_name,
)
from overseer.verdict import (
    Maintenance,
    ReportedComponent,
    ReportedRobot,
    Settings,
    Verdict,
    down_text,
    judge,
    maintenance_text,
)

HOST_UP, HOST_DOWN = 0, 1
ResultKey = tuple[str, str]  # a host, and one of its services or '' for the host itself


@dataclass(frozen=True, slots=True)
class CheckResult:
    """One result for `POST /v1/actions/process-check-result`; `service` is '' for the host itself."""

    host: str
    service: str
    exit_status: int
    plugin_output: str
    performance_data: tuple[str, ...]

    @property
    def key(self) -> ResultKey:
        """What this result replaces: the previous pending result of the same object."""
        return self.host, self.service


def robot_groups(robot: RobotState) -> list[str]:
    """The groups of the robot's components, sorted."""
    return sorted({group for name, _ in robot.components if (group := group_of(name)) is not None})


def robot_results(
    snapshot: FleetSnapshot,
    robot: RobotState,
    kinds: tuple[str, ...],
    groups: list[str],
    maintenance: Maintenance | None = None,
) -> list[CheckResult]:
    """The host result and every service result of `robot` now; `kinds` holds robot and/or groups.

    `groups` are the group services to judge: the robot's groups now and any it had before, which the
    check then judges as it would (UNKNOWN, no component matches) instead of leaving them frozen.
    `maintenance` is the window the robot is in, which every result names.
    """
    judged = judged_robot(snapshot, robot, maintenance)
    host = host_name(robot.name)
    up = judged.up
    host_text = f"UP - {judged.name}: diagnostics arriving"
    if not up:
        host_text = f"DOWN - {judged.name} is down: {down_text(judged)}"
    if maintenance is not None:
        host_text += maintenance_text(maintenance)
    results = [CheckResult(host, "", HOST_UP if up else HOST_DOWN, host_text, ())]
    for service, group in robot_services(kinds, groups):
        settings = Settings() if group is None else Settings(name_regex=re.compile(group_pattern(group)))
        results.append(service_result(host, service, judge(judged, settings)))
    return results


def robot_services(kinds: tuple[str, ...], groups: list[str]) -> list[tuple[str, str | None]]:
    """A robot's services for `kinds` and `groups`: each one's name and its group (None: the whole robot)."""
    services: list[tuple[str, str | None]] = []
    if "robot" in kinds:
        services.append((ROBOT_SERVICE, None))
    if "groups" in kinds:
        services.extend((group_service_name(group), group) for group in groups)
    return services


def judged_robot(
    snapshot: FleetSnapshot, robot: RobotState, maintenance: Maintenance | None = None
) -> ReportedRobot:
    """The robot as the verdict reads it: what `GET /api/v1/robots/<robot>` shows of it, now."""
    up = snapshot.robot_up(robot)
    components = [
        ReportedComponent(
            component.name,
            component.hardware_id,
            int(snapshot.component_level(robot, key, component, up)),
            component.message,
            list(component.values),
        )
        for key, component in sorted(robot.components.items())
    ]
    return ReportedRobot(
        robot.name,
        up,
        robot.last_message_wall,
        snapshot.generated_at,
        components,
        robot.publisher_alive,
        maintenance,
        robot.listing is not None,
    )


def service_result(host: str, service: str, verdict: Verdict) -> CheckResult:
    """A verdict as Icinga 2 stores a check result: text with long output, and perfdata items."""
    output = "\n".join([verdict.status_text, *verdict.long_output()])
    return CheckResult(host, service, verdict.state, output, tuple(verdict.perfdata))
