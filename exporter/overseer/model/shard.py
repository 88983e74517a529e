"""Sharding a fleet across exporters by a stable hash of the robot name."""

from __future__ import annotations

import zlib
from dataclasses import dataclass


@dataclass(frozen=True)
class Shard:
    """Shard `index` of `count`: it follows exactly the robots whose name hashes to `index`."""

    index: int = 0
    count: int = 1

    def owns(self, robot: str) -> bool:
        """True when this shard follows `robot`; every robot is owned by exactly one shard."""
        # CRC-32 is the same in every process and on every machine, unlike hash().
        return self.count == 1 or zlib.crc32(robot.encode("utf-8")) % self.count == self.index

    def __str__(self) -> str:
        """The `i/n` form used by the flag and the config."""
        return f"{self.index}/{self.count}"
