"""The one interface every output reads the fleet through, however many processes hold it.

`LocalFleet` is a fleet model in this process; `PooledFleet` is a pool of ingest workers, each holding
the robots it follows. Outputs (the HTTP endpoint, the Icinga 2 push, the event history) are written
once against this interface and never know which one they read.
"""

from __future__ import annotations

from collections.abc import Collection
from dataclasses import dataclass, field
from typing import Any, Protocol

from prometheus_client.registry import Collector

from overseer.fleet.documents import ComponentQuery, RobotQuery
from overseer.fleet.exposition import ExpositionPart
from overseer.model import FleetSnapshot, Inventory, RememberedRobot


@dataclass(frozen=True)
class FleetStart:
    """What a fleet follows before it hears anything: the inventory's robots, and those heard before."""

    inventory: Inventory = field(default_factory=Inventory)
    remembered: tuple[RememberedRobot, ...] = ()


class FleetPartUnavailable(RuntimeError):
    """Part of the fleet cannot be read now (an ingest worker is restarting): the endpoint answers 503."""


class Fleet(Protocol):
    """What outputs need of the fleet: snapshots, rendered series with counters, API documents."""

    def start(self) -> None:
        """Begin following robots; an error when a part cannot start."""
        ...

    def stop(self) -> None:
        """Stop following robots and release everything."""
        ...

    def robot_digests(self) -> dict[str, int | None]:
        """Every robot followed → a number that moves with its up or down or a level.

        None for a robot awaiting its first word since this start (`level_digests`). Digests are worked
        out again only for robots that changed, so they are kept between calls: for one reader, the push.
        `FleetPartUnavailable` rather than a fleet missing a part: the push would delete its robots' hosts.
        """
        ...

    def robots_snapshot(self, names: Collection[str]) -> FleetSnapshot:
        """A snapshot of the robots named that are followed, others left out; raises as `robot_digests`."""
        ...

    def exposition_parts(self) -> list[ExpositionPart]:
        """Every model's rendered series and counters, for an assembler to write out in a format."""
        ...

    def prepare_exposition(self) -> None:
        """Render now what changed, so that the next `exposition_parts` has less left to render."""
        ...

    def robots_document(self, query: RobotQuery | None = None) -> dict[str, Any]:
        """GET /api/v1/robots: every robot, or those `query` selects."""
        ...

    def robot_names(self) -> list[str]:
        """The names of the robots `robots_document` lists, in no order, without their documents."""
        ...

    def robot_document(self, name: str) -> dict[str, Any] | None:
        """GET /api/v1/robots/<name>, or None for a robot nobody follows; `FleetPartUnavailable` meanwhile."""
        ...

    def components_document(self, query: ComponentQuery) -> dict[str, Any]:
        """GET /api/v1/components."""
        ...

    def collectors(self) -> list[Collector]:
        """The fleet's own metrics beyond the series (how its workers fare), appended to /metrics."""
        ...

    def set_inventory(self, inventory: Inventory) -> None:
        """Follow `inventory` from now on: its robots, their labels and expected components."""
        ...

    def retire(self, robot: str) -> str:
        """Forget a robot that is down and not listed: 'retired', or why not: 'unknown', 'listed', 'up'."""
        ...

    def heard(self, with_components: bool = False) -> list[RememberedRobot]:
        """Every robot heard (in this run or before it) and when it was last heard; raises as `robot_digests`.

        `with_components` adds what each reported, for a clean stop.
        """
        ...
