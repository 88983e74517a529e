"""What to tell Icinga 2 about one robot: its host's state and each service's check result.

Each service's result is exactly what `check_ros_diagnostics` prints for the robot (and, for a group
service, for `--name-regex '^/<Group>(/|$)'`): it is judged by the check's own report code from the
very document the check reads, `serve/api.robot_document`.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

from overseer.check.report import Settings, down_text, judge, robot_from_document
from overseer.model import FleetSnapshot, RobotState
from overseer.push.icinga2_names import (
    ROBOT_SERVICE,
    group_of,
    group_pattern,
    group_service_name,
    host_name,
)
from overseer.serve.api import robot_document

HOST_UP, HOST_DOWN = 0, 1


@dataclass(frozen=True, slots=True)
class CheckResult:
    """One result for `POST /v1/actions/process-check-result`; `service` is '' for the host itself."""

    host: str
    service: str
    exit_status: int
    plugin_output: str
    performance_data: tuple[str, ...]

    @property
    def key(self) -> tuple[str, str]:
        """What this result replaces: the previous pending result of the same object."""
        return self.host, self.service


def robot_signature(snapshot: FleetSnapshot, robot: RobotState) -> tuple[object, ...]:
    """What a change of must be pushed at once: up or down, and every component's level now."""
    up = snapshot.robot_up(robot)
    return (up, tuple(robot.components), tuple(snapshot.component_levels(robot, up)))


def robot_groups(robot: RobotState) -> list[str]:
    """The groups of the robot's components, sorted."""
    return sorted({group for name, _ in robot.components if (group := group_of(name)) is not None})


def robot_results(
    snapshot: FleetSnapshot, robot: RobotState, kinds: tuple[str, ...], groups: list[str]
) -> list[CheckResult]:
    """The host result and every service result of `robot` now; `kinds` holds robot and/or groups.

    `groups` are the group services to judge: the robot's groups now and any it had before, which the
    check then judges as it would (UNKNOWN, no component matches) instead of leaving them frozen.
    """
    document = robot_document(snapshot, robot)
    judged = robot_from_document(document)
    host = host_name(robot.name)
    up = bool(document["up"])
    results = [
        CheckResult(
            host,
            "",
            HOST_UP if up else HOST_DOWN,
            f"UP - {judged.name}: diagnostics arriving"
            if up
            else f"DOWN - {judged.name} is down: {down_text(judged)}",
            (),
        )
    ]
    if "robot" in kinds:
        results.append(service_result(host, ROBOT_SERVICE, *judge(judged, Settings())))
    if "groups" in kinds:
        for group in groups:
            settings = Settings(name_regex=re.compile(group_pattern(group)))
            results.append(service_result(host, group_service_name(group), *judge(judged, settings)))
    return results


def service_result(host: str, service: str, state: int, output: str) -> CheckResult:
    """A check's printed output split as Icinga 2 stores it: text with long output, and perfdata items."""
    first_line, newline, long_output = output.partition("\n")
    text, bar, perfdata = first_line.partition(" | ")
    return CheckResult(
        host, service, state, text + newline + long_output, split_perfdata(perfdata) if bar else ()
    )


def split_perfdata(text: str) -> tuple[str, ...]:
    """Perfdata items split on spaces outside quoted labels (`'a b'=1;;;0 'c'=2`)."""
    items: list[str] = []
    current: list[str] = []
    quoted = False
    for char in text:
        if char == "'":
            quoted = not quoted  # a doubled quote toggles twice: still inside
        if char == " " and not quoted:
            if current:
                items.append("".join(current))
                current = []
            continue
        current.append(char)
    if current:
        items.append("".join(current))
    return tuple(items)
