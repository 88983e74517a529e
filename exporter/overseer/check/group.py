"""The check of a group of robots, chosen by their inventory labels: one state, one line, the robots listed.

Each robot is judged from its summary in `GET /api/v1/robots?label=...` as the one-robot check would
judge it: its level (ERROR CRITICAL, WARN WARNING, OK OK, STALE the stale state), or the stale state when
it is down. A robot in a maintenance window is listed, not judged: Icinga's downtime keeps one robot
quiet, and a site's service must not page for it either. Only the standard library's cheapest modules
are used here (the check's start-up).
"""

from __future__ import annotations

from overseer.check.document import (
    CheckError,
    flag_field,
    list_field,
    maintenance_from_document,
    number_field,
    text_field,
)
from overseer.verdict import (
    CRITICAL,
    OK,
    STALE_LEVEL,
    STATE_NAMES,
    UNKNOWN,
    WARNING,
    Maintenance,
    Verdict,
    clean,
    worst_state,
)

_SUMMARY_ROBOTS = 3
_STATES_BY_LEVEL = (OK, WARNING, CRITICAL)
_DOWN_REASONS = {
    "never_heard": "never heard",
    "publisher_left": "its publisher left",
    "silent": "silent",
}


class RobotSummary:
    """One robot as `GET /api/v1/robots` sums it up."""

    __slots__ = ("counts", "down_reason", "last_message", "level", "listed", "maintenance", "name", "up")

    def __init__(
        self,
        name: str,
        level: int,
        up: bool,
        down_reason: str,
        counts: dict[str, int],
        last_message: float | None,
        listed: bool,
        maintenance: Maintenance | None,
    ) -> None:
        """Keep the fields; `down_reason` is '' while the robot is up."""
        self.name = name
        self.level = level
        self.up = up
        self.down_reason = down_reason
        self.counts = counts
        self.last_message = last_message
        self.listed = listed
        self.maintenance = maintenance


def summaries_from_document(document: object) -> tuple[list[RobotSummary], float]:
    """The robots of a `GET /api/v1/robots` answer and its time; CheckError naming what is wrong."""
    if not isinstance(document, dict):
        raise CheckError("the answer is not a JSON object")
    robots = [_summary(item) for item in list_field(document, "robots")]
    return robots, number_field(document, "generated_at")


def _summary(document: object) -> RobotSummary:
    if not isinstance(document, dict):
        raise CheckError("a robot is not a JSON object")
    level = document.get("level")
    if level not in (0, 1, 2, 3) or not isinstance(level, int) or isinstance(level, bool):
        raise CheckError(f"robot level {level!r} is not 0, 1, 2 or 3")
    counts = document.get("counts")
    if not isinstance(counts, dict) or not all(
        isinstance(value, int) and not isinstance(value, bool) for value in counts.values()
    ):
        raise CheckError("'counts' is missing or not an object of numbers")
    last_message = document.get("last_message")
    reason = document.get("down_reason")
    return RobotSummary(
        name=text_field(document, "robot"),
        level=level,
        up=flag_field(document, "up"),
        down_reason=reason if isinstance(reason, str) else "",
        counts=counts,
        last_message=None if last_message is None else number_field(document, "last_message"),
        listed="listed" in document and flag_field(document, "listed"),
        maintenance=maintenance_from_document(document.get("maintenance")),
    )


def robot_state(robot: RobotSummary, stale_state: int) -> int:
    """A robot's Nagios state: its level's, or `stale_state` when it is down or STALE."""
    if not robot.up or robot.level == STALE_LEVEL:
        return stale_state
    return _STATES_BY_LEVEL[robot.level]


def judge_group(robots: list[RobotSummary], selection: str, stale_state: int, now: float) -> Verdict:
    """The verdict on the robots `selection` (e.g. `site=site_a`) chose, judged at `now` (unix time)."""
    if not robots:
        return GroupVerdict(UNKNOWN, f"no robot with {clean(selection)}", [], [])
    robots = sorted(robots, key=lambda robot: robot.name)
    judged = [robot for robot in robots if robot.maintenance is None]
    resting = [robot for robot in robots if robot.maintenance is not None]
    states = [robot_state(robot, stale_state) for robot in judged]
    state = worst_state(states)
    titles = (
        "CRITICAL robot(s) list:",
        "WARNING robot(s) list:",
        "UNKNOWN robot(s) list:",
        "OK robot(s) list:",
    )
    members: list[list[str]] = [[] for _ in titles]
    for robot, robot_state_now in zip(judged, states, strict=True):
        members[(3, 1, 0, 2)[robot_state_now]].append(robot_line(robot, now))
    sections: list[tuple[str, list[str]]] = [
        (title, lines) for title, lines in zip(titles, members, strict=True) if lines
    ]
    if resting:
        sections.append(("In maintenance (not judged):", [robot_line(robot, now) for robot in resting]))
    count = len(robots)
    head = f"{count} robot{'s' if count != 1 else ''} with {clean(selection)}"
    if state == OK:
        text = f"{head}: {len(judged)} OK" + (f", {len(resting)} in maintenance" if resting else "")
    else:
        worst = [robot for robot, s in zip(judged, states, strict=True) if s == state]
        named = ", ".join(
            f"{clean(robot.name)} ({robot_reason(robot, now)})" for robot in worst[:_SUMMARY_ROBOTS]
        )
        more = len(worst) - _SUMMARY_ROBOTS
        others = [
            f"{states.count(other)} {STATE_NAMES[other]}"
            for other in (CRITICAL, WARNING, UNKNOWN)
            if other != state and states.count(other)
        ]
        text = f"{head}: {named}" + (f" and {more} more" if more > 0 else "")
        text += f" (also {', '.join(others)})" if others else ""
    down = sum(1 for robot in judged if not robot.up)
    perfdata = [f"'robots'={count};;;0"] + [
        f"'{STATE_NAMES[s].lower()}'={states.count(s)};;;0" for s in (CRITICAL, WARNING, UNKNOWN, OK)
    ]
    perfdata += [f"'down'={down};;;0", f"'maintenance'={len(resting)};;;0"]
    return GroupVerdict(state, text, sections, perfdata)


def robot_reason(robot: RobotSummary, now: float) -> str:
    """Why a robot is in its state, in a few words: down and why, or its counts of problems."""
    if not robot.up:
        reason = _DOWN_REASONS.get(robot.down_reason, "down")
        if robot.down_reason == "silent" and robot.last_message is not None:
            reason = f"silent for {max(0, round(now - robot.last_message))} s"
        if robot.down_reason == "never_heard" and robot.listed:
            reason += ", listed in the inventory"
        return f"down: {reason}"
    problems = [
        f"{robot.counts.get(key, 0)} {name}"
        for key, name in (("error", "ERROR"), ("warn", "WARN"), ("stale", "STALE"))
        if robot.counts.get(key, 0)
    ]
    return ", ".join(problems) or f"{robot.counts.get('ok', 0)} OK"


def robot_line(robot: RobotSummary, now: float) -> str:
    """One robot in the long output: its name and `robot_reason`."""
    return f"{clean(robot.name)}: {robot_reason(robot, now)}"


class GroupVerdict(Verdict):
    """A verdict whose sections list robots, each one line already written, rather than components."""

    __slots__ = ("robot_sections",)

    def __init__(
        self, state: int, summary: str, robot_sections: list[tuple[str, list[str]]], perfdata: list[str]
    ) -> None:
        """Keep the fields."""
        super().__init__(state, summary, [], perfdata)
        self.robot_sections = robot_sections

    def long_output(self, verbosity: int = 0) -> list[str]:
        """Each section's title, then its robots."""
        lines: list[str] = []
        for title, members in self.robot_sections:
            lines.append(title)
            lines.extend(members)
        return lines
