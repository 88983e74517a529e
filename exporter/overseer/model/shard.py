"""Sharding a fleet across exporters, and an exporter's robots across its ingest workers.

Both split by the same stable hash of the robot name: shard `i/n` follows the robots whose hash is `i`
modulo `n`, and of those, worker `w` of `k` follows the ones whose remaining hash (the hash divided by
`n`) is `w` modulo `k`. A robot's topics all carry its name, so they all land in one worker, and every
robot of the shard lands in exactly one.
"""

from __future__ import annotations

import zlib
from dataclasses import dataclass, replace


@dataclass(frozen=True)
class Shard:
    """Shard `index` of `count`, narrowed to ingest worker `worker` of `workers`."""

    index: int = 0
    count: int = 1
    worker: int = 0
    workers: int = 1

    def owns(self, robot: str) -> bool:
        """True when this shard (and worker) follows `robot`; every robot is owned by exactly one."""
        if self.count == 1 and self.workers == 1:
            return True
        # CRC-32 is the same in every process and on every machine, unlike hash().
        digest = zlib.crc32(robot.encode("utf-8"))
        return digest % self.count == self.index and (digest // self.count) % self.workers == self.worker

    def worker_of(self, robot: str, workers: int) -> int | None:
        """Which of `workers` workers of this shard follows `robot`; None when another shard does."""
        digest = zlib.crc32(robot.encode("utf-8"))
        if digest % self.count != self.index:
            return None
        return (digest // self.count) % workers

    def for_worker(self, worker: int, workers: int) -> Shard:
        """The part of this shard that ingest worker `worker` of `workers` follows."""
        if not 0 <= worker < workers:
            raise ValueError(f"worker {worker} is not one of 0-{workers - 1}")
        return replace(self, worker=worker, workers=workers)

    def __str__(self) -> str:
        """The `i/n` form used by the flag and the config."""
        return f"{self.index}/{self.count}"
