"""The fleet model: what the transports write and every view reads.

`state` holds the records, `snapshot` the time-dependent judgements over them, `fleet` the live model
behind its lock, `inventory` the robots and components the fleet should have, `shard` which robots this
exporter follows.
"""

from overseer.model.fleet import Applied, FleetModel, LevelChange, LevelListener
from overseer.model.inventory import Inventory
from overseer.model.snapshot import FleetSnapshot
from overseer.model.state import (
    Component,
    ComponentKey,
    Expectation,
    FleetLimits,
    ListedRobot,
    RememberedRobot,
    RobotState,
)

__all__ = [
    "Applied",
    "Component",
    "ComponentKey",
    "Expectation",
    "FleetLimits",
    "FleetModel",
    "FleetSnapshot",
    "Inventory",
    "LevelChange",
    "LevelListener",
    "ListedRobot",
    "RememberedRobot",
    "RobotState",
]
