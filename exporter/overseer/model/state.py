"""What the model holds: a robot's state, its components' last statuses, and the limits that bound them.

Robot states are immutable and replaced whole on every message, so a snapshot of the fleet is a shallow
copy of them.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import NamedTuple

from overseer.levels import Level

ComponentKey = tuple[str, str]  # (name, hardware_id)


@dataclass(frozen=True)
class FleetLimits:
    """Time limits and caps that bound what the model keeps."""

    stale_after: float = 5.0
    robot_timeout: float = 10.0
    expire_after: float = 3600.0
    max_robots: int = 10_000
    max_components_per_robot: int = 1_000
    max_values_per_component: int = 64
    max_string_length: int = 1_024


class Component(NamedTuple):
    """The last status a component reported; `level` is the reported level, before staleness.

    `last_update` is when it was last reported in a message other than its robot's latest one; while it
    is in the latest message, `FleetSnapshot.last_update` gives that message's time instead. This lets
    an unchanged message refresh a whole robot by replacing one `RobotState`. A named tuple, not a frozen
    dataclass: it is built for every status that changed, and a frozen dataclass is four times slower
    to build. `key` is the very tuple that keys it in its robot's components (and in `latest`).
    """

    key: ComponentKey
    level: Level
    message: str
    values: tuple[tuple[str, str], ...]
    last_update: float
    level_changes: int
    topic: str

    @property
    def name(self) -> str:
        """The status's name."""
        return self.key[0]

    @property
    def hardware_id(self) -> str:
        """The status's hardware_id."""
        return self.key[1]


@dataclass(frozen=True, slots=True)
class RobotState:
    """One robot as last seen; replaced whole, never mutated.

    `latest` holds, in the message's order, the component each status of the latest message went to,
    or None where the status lost something (dropped, cut short, or a repeated name): an ingest may
    then apply only the statuses that changed (`FleetModel.apply_changes`). `missing` holds the
    components absent from the latest message; it is empty for almost every robot, so it is shared.
    `publisher_alive` is False while a transport that tracks publishers (Zenoh liveliness) knows the
    robot's diagnostics publisher is gone: the robot is down at once, before `robot_timeout`.
    """

    name: str
    transport: str
    last_message: float | None
    components: Mapping[ComponentKey, Component]
    discovered_at: float
    revision: int = 0
    latest: tuple[ComponentKey | None, ...] = ()
    missing: frozenset[ComponentKey] = frozenset()
    publisher_alive: bool = True  # False once the transport saw the robot's publisher go (liveliness)

    @property
    def last_seen(self) -> float:
        """When the robot last sent a message, or when it was discovered if it never did."""
        return self.discovered_at if self.last_message is None else self.last_message
