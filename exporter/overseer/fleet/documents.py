"""The fleet as the JSON API shows it: robots, one robot, components matching a query, from a snapshot."""

from __future__ import annotations

import heapq
from collections.abc import Iterator
from dataclasses import dataclass
from itertools import chain, compress
from operator import itemgetter
from typing import Any

from overseer.levels import Level, severity_rank, worst
from overseer.model import Component, FleetSnapshot, RobotState
from overseer.model.inventory import is_stand_in
from overseer.model.state import learned_period

_COUNT_NAMES = tuple((level, level.name.lower()) for level in Level)


@dataclass(frozen=True)
class RobotQuery:
    """Which robots GET /api/v1/robots returns: those with every one of `labels` (name, value).

    An empty value asks for robots without the label, as a Prometheus matcher `site=""` does.
    """

    labels: tuple[tuple[str, str], ...] = ()

    def matches(self, robot: RobotState) -> bool:
        """True when `robot` carries every label asked for."""
        have = dict(robot.listing.labels) if robot.listing is not None else {}
        return all(have.get(name, "") == value for name, value in self.labels)


def robots_document(snapshot: FleetSnapshot, query: RobotQuery | None = None) -> dict[str, Any]:
    """GET /api/v1/robots: every robot's summary, or those `query` selects."""
    robots = [robot for robot in snapshot.robots if query is None or query.matches(robot)]
    return {
        "generated_at": snapshot.generated_at,
        "robots": [_robot_summary(snapshot, robot) for robot in sorted(robots, key=lambda r: r.name)],
    }


def robot_document(snapshot: FleetSnapshot, robot: RobotState) -> dict[str, Any]:
    """GET /api/v1/robots/<robot>: one robot with every component."""
    up = snapshot.robot_up(robot)
    listing = robot.listing
    components = []
    for key, component in sorted(robot.components.items()):
        level = snapshot.component_level(robot, key, component, up)
        reported = not is_stand_in(component)
        components.append(
            {
                "name": component.name,
                "hardware_id": component.hardware_id,
                "level": int(level),
                "state": level.name,
                "reported_level": int(component.level),
                "stale": level is Level.STALE,
                "message": component.message,
                "values": [{"key": key, "value": value} for key, value in component.values],
                "last_update": robot.wall_time(snapshot.last_update(robot, key, component))
                if reported
                else None,
                "stale_after": snapshot.stale_after(robot, component),
                "level_changes": component.level_changes,
                "reported": reported,
                "expected": not reported or (listing is not None and listing.expects(component.name)),
            }
        )
    document = _robot_summary(snapshot, robot)
    document["components"] = components
    return {"generated_at": snapshot.generated_at, **document}


def _robot_summary(snapshot: FleetSnapshot, robot: RobotState) -> dict[str, Any]:
    up = snapshot.robot_up(robot)
    # One pass of the snapshot's bulk judgement; list.count compares in C (1,000 robots: the page waits on it)
    levels = snapshot.component_levels(robot, up)
    counts = {name: levels.count(level) for level, name in _COUNT_NAMES}
    level = worst(level for level, name in _COUNT_NAMES if counts[name]) if up else Level.STALE
    return {
        "robot": robot.name,
        "level": int(level),
        "state": level.name,
        "up": up,
        "down_reason": None if up else down_reason(robot),
        "labels": dict(robot.listing.labels) if robot.listing is not None else {},
        "listed": robot.listing is not None,
        "publisher_alive": robot.publisher_alive,
        "last_message": robot.last_message_wall,
        "period": learned_period(robot),
        "timeout": snapshot.robot_timeout(robot),
        "transport": robot.transport,
        "components": len(robot.components),
        "counts": counts,
    }


def down_reason(robot: RobotState) -> str:
    """Why a robot that is down is: never_heard, publisher_left or silent."""
    if robot.last_message is None:
        return "never_heard"
    return "silent" if robot.publisher_alive else "publisher_left"


COMPONENTS_DEFAULT_LIMIT = 100
COMPONENTS_MAX_LIMIT = 1000


@dataclass(frozen=True)
class ComponentQuery:
    """Which components GET /api/v1/components returns: levels (None: any), text, robot, how many."""

    levels: frozenset[Level] | None = None
    text: str = ""
    robot: str | None = None
    limit: int = COMPONENTS_DEFAULT_LIMIT


def components_document(snapshot: FleetSnapshot, query: ComponentQuery) -> dict[str, Any]:
    """GET /api/v1/components: the components matching `query` across the fleet, worst first, bounded.

    Text matches case-insensitively anywhere in the robot's name, the component's name, its hardware_id
    or its message. `total` counts every match; `robots` lists every robot with a match and how many.
    """
    needle = query.text.casefold()
    wanted = query.levels
    matches: list[tuple[int, str, str, str, Component, Level]] = []
    per_robot: dict[str, int] = {}
    for robot in snapshot.robots:
        if query.robot is not None and robot.name != query.robot:
            continue
        robot_matches = not needle or needle in robot.name.casefold()
        if not robot_matches and wanted is None and not _may_mention(robot, needle):
            continue
        levels = snapshot.component_levels(robot, snapshot.robot_up(robot))
        candidates: Iterator[tuple[Component, Level]] = zip(robot.components.values(), levels, strict=True)
        if wanted is not None:
            # the levels asked for, picked in C: a fleet has few components in trouble
            candidates = compress(candidates, map(wanted.__contains__, levels))
        count = 0
        for component, level in candidates:
            if not (
                robot_matches
                or needle in component.name.casefold()
                or needle in component.message.casefold()
                or needle in component.hardware_id.casefold()
            ):
                continue
            count += 1
            matches.append((-severity_rank(level), robot.name, *component.key, component, level))
        if count:
            per_robot[robot.name] = count
    # component_levels follows robot.components' order, so last_update needs the robot again
    robots = {robot.name: robot for robot in snapshot.robots}
    chosen = heapq.nsmallest(query.limit, matches, key=lambda match: match[:4])
    return {
        "generated_at": snapshot.generated_at,
        "total": len(matches),
        "limit": query.limit,
        "truncated": len(matches) > len(chosen),
        "components": [
            {
                "robot": robot_name,
                "name": component.name,
                "hardware_id": component.hardware_id,
                "level": int(level),
                "state": level.name,
                "message": component.message,
                "last_update": robots[robot_name].wall_time(
                    snapshot.last_update(robots[robot_name], component.key, component)
                )
                if not is_stand_in(component)
                else None,
                "reported": not is_stand_in(component),
            }
            for _, robot_name, _, _, component, level in chosen
        ],
        "robots": [{"robot": name, "matches": count} for name, count in sorted(per_robot.items())],
    }


_NAME = itemgetter(0)  # of a robot's component keys
_MESSAGE = itemgetter(Component._fields.index("message"))
_HARDWARE_ID = itemgetter(Component._fields.index("hardware_id"))


def _may_mention(robot: RobotState, needle: str) -> bool:
    """False when no component of `robot` has `needle` in its name, message or hardware_id.

    Each text of the robot is joined into one string and searched at once, in C; True only says that a
    component may match (the needle may span two joined texts), for the exact test to decide.
    """
    components = robot.components
    values = components.values()
    texts = "\n".join(chain(map(_NAME, components), map(_MESSAGE, values), map(_HARDWARE_ID, values)))
    return needle in texts.casefold()
