"""Joining the workers' answers into the one fleet they share out: robots are disjoint, counters add up."""

from __future__ import annotations

import heapq
import threading
from collections.abc import Iterable, Mapping, Sequence
from types import MappingProxyType
from typing import Any

from overseer.fleet.deflated import EMPTY
from overseer.fleet.exposition import ExpositionPart
from overseer.fleet.metric_families import FLEET_FAMILIES
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


def portable_robots(snapshot: FleetSnapshot) -> list[RobotState]:
    """The snapshot's robots in a form that pickles (a plain dict for the read-only components view)."""
    return [_with_components(robot, dict(robot.components)) for robot in snapshot.robots]


def merge_snapshots(
    parts: Sequence[FleetSnapshot], limits: FleetLimits, taken_at: float, generated_at: float
) -> FleetSnapshot:
    """One snapshot of the fleet from the workers' snapshots (their robots made read-only again).

    `taken_at` is the monotonic time it is judged at, `generated_at` the wall clock then.
    """
    robots = tuple(
        _with_components(robot, MappingProxyType(robot.components)) for part in parts for robot in part.robots
    )
    counts: dict[tuple[str, str], int] = {}
    dropped: dict[str, int] = {}
    errors: dict[tuple[str, str], int] = {}
    forgotten_counts: dict[str, int] = {}
    for part in parts:
        _add(counts, part.message_counts)
        _add(dropped, part.dropped_statuses)
        _add(errors, part.source_errors)
        _add(forgotten_counts, part.forgotten_counts)
    truncated = sum(part.truncated_strings for part in parts)
    forgotten = {name: forgetting for part in parts for name, forgetting in part.forgotten.items()}
    return FleetSnapshot(
        taken_at,
        limits,
        robots,
        counts,
        dropped,
        truncated,
        errors,
        generated_at,
        forgotten,
        forgotten_counts,
    )


def _add(total: dict[Any, Any], counts: Any) -> None:
    for key, count in counts.items():
        total[key] = total.get(key, 0) + count


def _with_components(robot: RobotState, components: Any) -> RobotState:
    return robot._replace(components=components)


CounterKey = tuple[Any, ...]


class CounterCarry:
    """Keeps the workers' exporter-wide counters from going back when a worker restarts or misses a scrape.

    Prometheus takes any drop of a counter for a reset: a restarted worker's counters start again from
    zero, and a worker that cannot answer one scrape would leave its share out. So the exporter keeps each
    worker's last counters, serves them while it does not answer, and adds them to a base once the worker
    answers as a new process (a new generation).
    """

    def __init__(self, workers: int) -> None:
        """Counters of `workers` workers, none seen yet."""
        self._base: list[dict[CounterKey, float]] = [{} for _ in range(workers)]
        self._last: list[dict[CounterKey, float]] = [{} for _ in range(workers)]
        self._generation = [0] * workers
        self._lock = threading.Lock()

    def totals(
        self, answers: Iterable[tuple[int, int, Mapping[CounterKey, float]]]
    ) -> dict[CounterKey, float]:
        """The fleet's counters given (worker, generation, its counters) of the workers that answered."""
        with self._lock:
            for worker, generation, counts in answers:
                last = self._last[worker]
                if generation != self._generation[worker]:
                    _add(self._base[worker], last)
                    last = self._last[worker] = {}
                    self._generation[worker] = generation
                for key, value in counts.items():  # the larger: answers of concurrent scrapes may cross
                    if value >= last.get(key, 0):
                        last[key] = value
            totals: dict[CounterKey, float] = {}
            for base, last in zip(self._base, self._last, strict=True):
                _add(totals, base)
                _add(totals, last)
            return totals


def part_counters(part: ExpositionPart) -> dict[CounterKey, float]:
    """An exposition part's counters under one kind of key."""
    counts: dict[CounterKey, float] = {
        ("messages", *key): value for key, value in part.message_counts.items()
    }
    counts.update({("dropped", reason): value for reason, value in part.dropped_statuses.items()})
    counts.update({("errors", *key): value for key, value in part.source_errors.items()})
    counts.update({("forgotten", reason): value for reason, value in part.forgotten.items()})
    counts[("truncated",)] = part.truncated_strings
    return counts


def counters_part(counts: Mapping[CounterKey, float]) -> ExpositionPart:
    """An exposition part with no series, carrying `counts` (as `part_counters` keys them)."""
    messages, dropped, errors, forgotten, truncated = {}, {}, {}, {}, 0
    for key, value in counts.items():
        if key[0] == "messages":
            messages[key[1:]] = int(value)
        elif key[0] == "dropped":
            dropped[key[1]] = int(value)
        elif key[0] == "errors":
            errors[key[1:]] = int(value)
        elif key[0] == "forgotten":
            forgotten[key[1]] = int(value)
        else:
            truncated = int(value)
    return ExpositionPart(0, (EMPTY,) * len(FLEET_FAMILIES), messages, dropped, truncated, errors, forgotten)
