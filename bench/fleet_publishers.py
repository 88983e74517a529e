"""Simulated fleets for the end-to-end benchmarks: one `overseer simulate` process per 2,500 robots."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from collections.abc import Sequence

SIMULATOR_ROBOTS = 2500  # one Python process cannot build and send more arrays than this at 1 Hz


def start_publishers(
    robots: int,
    components: int,
    seconds: float,
    transport_args: Sequence[str],
    vary_values: str,
    per_process: int = SIMULATOR_ROBOTS,
    env: dict[str, str] | None = None,
) -> list[subprocess.Popen[str]]:
    """Start publishing `robots` x `components` at 1 Hz for `seconds`, once every robot has a subscriber.

    Robots are named `s<process>/robot<n>`, `per_process` a process; `transport_args` choose DDS, Zenoh or
    ROS 2 and their endpoints; `env` adds to the publishers' environment.
    """
    shares = [min(per_process, robots - first) for first in range(0, robots, per_process)]
    return [
        subprocess.Popen(
            [
                sys.executable,
                "-m",
                "overseer.cli",
                "simulate",
                *transport_args,
                f"--robots={share}",
                f"--namespace-prefix=s{index}/robot",
                f"--components={components}",
                "--warn=1",
                "--error=1",
                f"--vary-values={vary_values}",
                "--wait-for-subscribers=900",
                f"--duration={seconds}",
                "--log.level=warning",
            ],
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
            env={**os.environ, **(env or {})},
        )
        for index, share in enumerate(shares)
    ]


def messages_published(publishers: Sequence[subprocess.Popen[str]], timeout: float) -> int:
    """Wait for every publisher to end; the messages they wrote in all (RuntimeError if one failed)."""
    published = 0
    for publisher in publishers:
        stdout, stderr = publisher.communicate(timeout=timeout)
        match = re.search(r"published (\d+) messages", stdout)
        if publisher.returncode != 0 or match is None:
            raise RuntimeError(f"simulator failed: {stdout[-2000:]} {stderr[-2000:]}")
        published += int(match.group(1))
    return published
