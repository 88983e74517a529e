"""The /api/v1 view: fleet snapshots as JSON-ready dictionaries."""

from __future__ import annotations

from typing import Any

from overseer.levels import Level
from overseer.model import FleetSnapshot, RobotState


def robots_document(snapshot: FleetSnapshot) -> dict[str, Any]:
    """GET /api/v1/robots: every robot's summary."""
    return {
        "generated_at": snapshot.taken_at,
        "robots": [
            _robot_summary(snapshot, robot) for robot in sorted(snapshot.robots, key=lambda r: r.name)
        ],
    }


def robot_document(snapshot: FleetSnapshot, robot: RobotState) -> dict[str, Any]:
    """GET /api/v1/robots/<robot>: one robot with every component."""
    up = snapshot.robot_up(robot)
    components = []
    for key, component in sorted(robot.components.items()):
        level = snapshot.component_level(robot, key, component, up)
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
                "last_update": snapshot.last_update(robot, key, component),
                "level_changes": component.level_changes,
            }
        )
    document = _robot_summary(snapshot, robot)
    document["components"] = components
    return {"generated_at": snapshot.taken_at, **document}


def _robot_summary(snapshot: FleetSnapshot, robot: RobotState) -> dict[str, Any]:
    up = snapshot.robot_up(robot)
    counts = dict.fromkeys(("ok", "warn", "error", "stale"), 0)
    for key, component in robot.components.items():
        counts[snapshot.component_level(robot, key, component, up).name.lower()] += 1
    level = snapshot.robot_level(robot)
    return {
        "robot": robot.name,
        "level": int(level),
        "state": level.name,
        "up": up,
        "last_message": robot.last_message,
        "transport": robot.transport,
        "components": len(robot.components),
        "counts": counts,
    }
