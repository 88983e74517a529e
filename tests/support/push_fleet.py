"""A fleet model served to the Icinga 2 push as the exporter's fleet serves it, failing once if asked."""

from __future__ import annotations

from collections.abc import Collection
from dataclasses import replace

from overseer.fleet.interface import FleetPartUnavailable
from overseer.fleet.level_digests import Signatures
from overseer.model import FleetModel, FleetSnapshot


class FleetFailingOnce:
    """The robots of `model`, whose `robots_snapshot` fails on its `fail_at`-th call (a worker restarting)."""

    def __init__(self, model: FleetModel, fail_at: int) -> None:
        """Serve `model`; fail the `fail_at`-th ask."""
        self.model = model
        self.fail_at = fail_at
        self.asked: list[set[str]] = []
        self.forgotten: set[str] = set()  # robots the fleet no longer has
        self._signatures = Signatures()

    def robot_digests(self) -> dict[str, int | None]:
        """Every robot's digest but the forgotten's."""
        digests = self._signatures.digests(self.model.snapshot())
        return {name: digest for name, digest in digests.items() if name not in self.forgotten}

    def robots_snapshot(self, names: Collection[str]) -> FleetSnapshot:
        """The robots named, or FleetPartUnavailable on the `fail_at`-th call."""
        self.asked.append(set(names))
        if len(self.asked) == self.fail_at:
            raise FleetPartUnavailable("ingest worker 1 is restarting")
        snapshot = self.model.snapshot()
        return replace(snapshot, robots=tuple(robot for robot in snapshot.robots if robot.name in names))
