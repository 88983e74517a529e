"""Real ROS 2 Jazzy robots (rclpy from the pinned PyPI wheels) and a ROS graph to look at, on loopback.

Every process started here, and the test process's own node, keeps discovery on this host with
`ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST` and joins a domain of the test's own (`ROS_DOMAIN_ID`).
"""

from __future__ import annotations

import os
import sys
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from overseer.sources.ros2.node import RosNode
from testbed.paths import TESTBED
from testbed.processes import RunningProcess, spawn

ROBOT_SCRIPT = TESTBED / "ros2" / "robot.py"


def ros2_environment(domain: int) -> dict[str, str]:
    """The variables that put a ROS 2 process on `domain`, discovering on this host only."""
    return {"ROS_DOMAIN_ID": str(domain), "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST"}


def start_robot(tmp_path: Path, domain: int, *args: str, timeout: float = 30.0) -> RunningProcess:
    """Start a Jazzy robot (`testbed/ros2/robot.py` with `args`) and wait until it publishes."""
    log_path = tmp_path / f"ros2-robot-{time.monotonic_ns()}.log"
    robot = RunningProcess(
        spawn([sys.executable, str(ROBOT_SCRIPT), *args], log_path, env=ros2_environment(domain)), log_path
    )
    deadline = time.monotonic() + timeout
    while "ready" not in robot.log():
        if robot.process.poll() is not None:
            raise RuntimeError(f"ROS 2 robot exited with {robot.process.returncode}:\n{robot.log()}")
        if time.monotonic() > deadline:
            robot.stop()
            raise TimeoutError(f"ROS 2 robot not ready after {timeout}s:\n{robot.log()}")
        time.sleep(0.05)
    return robot


@contextmanager
def running_robots(tmp_path: Path, domain: int, *robots: tuple[str, ...]) -> Iterator[list[RunningProcess]]:
    """Jazzy robots, one per argument tuple, until the block ends (stopped cleanly then)."""
    started: list[RunningProcess] = []
    try:
        for args in robots:
            started.append(start_robot(tmp_path, domain, *args))
        yield started
    finally:
        for robot in started:
            robot.stop()


@contextmanager
def graph_node(domain: int, name: str = "observer") -> Iterator[RosNode]:
    """A node of the test process's own in `domain`, on loopback, for the length of the block."""
    previous = {key: os.environ.get(key) for key in ("ROS_AUTOMATIC_DISCOVERY_RANGE",)}
    os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    node = RosNode(name, domain)
    try:
        yield node
    finally:
        node.close()
        for key, value in previous.items():
            if value is None:
                os.environ.pop(key, None)
            else:
                os.environ[key] = value
