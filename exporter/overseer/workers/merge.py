"""Joining the workers' answers into the one fleet they share out: robots are disjoint, counters add up."""

from __future__ import annotations

import heapq
from collections.abc import Iterable, Iterator, Sequence
from types import MappingProxyType
from typing import Any

from prometheus_client.metrics_core import Metric
from prometheus_client.samples import Sample

from overseer.levels import Level, severity_rank
from overseer.model import FleetLimits, FleetSnapshot, RobotState


def merge_robots_documents(documents: Sequence[dict[str, Any]], generated_at: float) -> dict[str, Any]:
    """GET /api/v1/robots of the whole fleet from each worker's."""
    robots = [robot for document in documents for robot in document["robots"]]
    robots.sort(key=lambda robot: robot["robot"])
    return {"generated_at": generated_at, "robots": robots}


def merge_components_documents(
    documents: Sequence[dict[str, Any]], limit: int, generated_at: float
) -> dict[str, Any]:
    """GET /api/v1/components of the whole fleet from each worker's answer to the same query.

    Each worker returns its own first `limit` matches in the API's order (worst first, then robot,
    component and hardware_id), so the fleet's first `limit` are among them.
    """
    total = sum(document["total"] for document in documents)
    candidates = [component for document in documents for component in document["components"]]
    chosen = heapq.nsmallest(limit, candidates, key=_component_order)
    robots = [robot for document in documents for robot in document["robots"]]
    robots.sort(key=lambda robot: robot["robot"])
    return {
        "generated_at": generated_at,
        "total": total,
        "limit": limit,
        "truncated": total > len(chosen),
        "components": chosen,
        "robots": robots,
    }


def _component_order(component: dict[str, Any]) -> tuple[int, str, str, str]:
    level = Level(component["level"])
    return (-severity_rank(level), component["robot"], component["name"], component["hardware_id"])


def merge_families(answers: Iterable[Sequence[Metric]]) -> Iterator[Metric]:
    """The workers' metric families as one set: samples joined per family, counters with equal labels added.

    Per-robot series are each in one worker's answer only; the exporter-wide ones (counters, build info)
    are in every answer: counters are summed, the rest taken once.
    """
    merged: dict[str, Metric] = {}
    index: dict[str, dict[tuple[str, tuple[tuple[str, str], ...]], int]] = {}
    for families in answers:
        for family in families:
            target = merged.get(family.name)
            if target is None:
                target = merged[family.name] = Metric(family.name, family.documentation, family.type)
                index[family.name] = {}
            seen = index[family.name]
            for sample in family.samples:
                identity = (sample.name, tuple(sorted(sample.labels.items())))
                position = seen.get(identity)
                if position is None:
                    seen[identity] = len(target.samples)
                    target.samples.append(sample)
                elif family.type == "counter":
                    held = target.samples[position]
                    target.samples[position] = Sample(
                        held.name, held.labels, held.value + sample.value, held.timestamp, held.exemplar
                    )
    yield from merged.values()


def portable_robots(snapshot: FleetSnapshot) -> list[RobotState]:
    """The snapshot's robots in a form that pickles (a plain dict for the read-only components view)."""
    return [_with_components(robot, dict(robot.components)) for robot in snapshot.robots]


def merge_snapshots(parts: Sequence[FleetSnapshot], limits: FleetLimits, taken_at: float) -> FleetSnapshot:
    """One snapshot of the fleet from the workers' snapshots (their robots made read-only again)."""
    robots = tuple(
        _with_components(robot, MappingProxyType(robot.components)) for part in parts for robot in part.robots
    )
    counts: dict[tuple[str, str], int] = {}
    dropped: dict[str, int] = {}
    errors: dict[tuple[str, str], int] = {}
    for part in parts:
        _add(counts, part.message_counts)
        _add(dropped, part.dropped_statuses)
        _add(errors, part.source_errors)
    truncated = sum(part.truncated_strings for part in parts)
    return FleetSnapshot(taken_at, limits, robots, counts, dropped, truncated, errors)


def _add(total: dict[Any, int], counts: Any) -> None:
    for key, count in counts.items():
        total[key] = total.get(key, 0) + count


def _with_components(robot: RobotState, components: Any) -> RobotState:
    return RobotState(
        robot.name,
        robot.transport,
        robot.last_message,
        components,
        robot.discovered_at,
        robot.revision,
        robot.latest,
        robot.missing,
        robot.publisher_alive,
    )
