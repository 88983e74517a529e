"""The fleet model: what the transports write and every view reads.

`state` holds the records, `snapshot` the time-dependent judgements over them, `fleet` the live model
behind its lock, `shard` which robots this exporter follows.
"""

from overseer.model.fleet import Applied, FleetModel, LevelChange, LevelListener
from overseer.model.snapshot import FleetSnapshot
from overseer.model.state import Component, ComponentKey, FleetLimits, RobotState

__all__ = [
    "Applied",
    "Component",
    "ComponentKey",
    "FleetLimits",
    "FleetModel",
    "FleetSnapshot",
    "LevelChange",
    "LevelListener",
    "RobotState",
]
