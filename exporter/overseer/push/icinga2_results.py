"""What to tell Icinga 2 about one robot: its host's state and each service's check result.

Each service's result is exactly what `check_ros_diagnostics` prints for the robot (and, for a group
service, for `--name-regex '^/<Group>(/|$)'`): the same verdict (`overseer.verdict`), judged from the
snapshot the API document is made of, its parts handed to Icinga as they are (text and perfdata items).
"""

from __future__ import annotations

import bisect
import math
import re
from dataclasses import dataclass
from typing import NamedTuple

from overseer.model import FleetSnapshot, RobotState
from overseer.model.snapshot import RobotTiming
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


class _Known(NamedTuple):
    """What `Signatures` keeps of one robot."""

    robot: RobotState  # the version looked at last
    until: float  # until when (monotonic) that version's up and staleness hold
    key: tuple[object, ...]  # its revision, up and staleness
    timing: RobotTiming
    signature: tuple[object, ...]


class Signatures:
    """Each robot's `robot_signature`, worked out again only when a revision, up or staleness changed.

    At 10,000 robots, working every one out at every look of the push took a third of a core: a robot
    republishing the same array keeps its revision, its staleness holds between messages, and a robot
    not heard since the last look is the same version, whose levels hold until a component's bound or the
    robot's timeout passes.
    """

    def __init__(self) -> None:
        """Nothing known yet."""
        self._known: dict[str, _Known] = {}

    def of(self, snapshot: FleetSnapshot, robot: RobotState) -> tuple[object, ...]:
        """`robot_signature(snapshot, robot)`, from what was kept when nothing it depends on changed."""
        known = self._known.get(robot.name)
        if known is not None and known.robot is robot and snapshot.taken_at <= known.until:
            return known.signature
        # A robot forgotten and followed again starts its revisions over: its discovery tells them apart.
        revision = (robot.revision, robot.discovered_at)
        timing = known.timing if known is not None and known.key[0] == revision else snapshot.timing(robot)
        key = (revision, snapshot.robot_up(robot), snapshot.staleness(robot, timing))
        until = holds_until(snapshot, robot, timing)
        if known is not None and known.key == key:
            self._known[robot.name] = known._replace(robot=robot, until=until)
            return known.signature
        signature = robot_signature(snapshot, robot)
        self._known[robot.name] = _Known(robot, until, key, timing, signature)
        return signature

    def forget(self, name: str) -> None:
        """A robot gone from the fleet."""
        self._known.pop(name, None)


def holds_until(snapshot: FleetSnapshot, robot: RobotState, timing: RobotTiming) -> float:
    """The last time (monotonic) at which this version of `robot` is as up and as stale as at the snapshot."""
    taken_at = snapshot.taken_at
    until = math.inf
    if robot.last_message is not None and snapshot.robot_up(robot):  # down, it stays down: no bound
        until = robot.last_message + snapshot.robot_timeout(robot)
    for feed, bounds in zip(robot.feeds, timing.feed_bounds, strict=True):
        passed = bisect.bisect_left(bounds, taken_at - feed.last_message)
        if passed < len(bounds):
            until = min(until, feed.last_message + bounds[passed])
    passed = bisect.bisect_left(timing.own_deadlines, taken_at)
    if passed < len(timing.own_deadlines):
        until = min(until, timing.own_deadlines[passed])
    return until


def awaiting(snapshot: FleetSnapshot, robot: RobotState) -> bool:
    """True for a robot heard before this start, up then, not heard since: nothing new to push yet.

    Until it speaks again (or its timeout passes and it is down) Icinga's last results stand; pushing a
    robot whose components a crash left unknown would turn its services UNKNOWN for a few seconds.
    """
    return robot.last_message is not None and not robot.feeds and snapshot.robot_up(robot)


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
    if "robot" in kinds:
        results.append(service_result(host, ROBOT_SERVICE, judge(judged, Settings())))
    if "groups" in kinds:
        for group in groups:
            settings = Settings(name_regex=re.compile(group_pattern(group)))
            results.append(service_result(host, group_service_name(group), judge(judged, settings)))
    return results


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
