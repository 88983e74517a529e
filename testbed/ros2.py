"""Real ROS 2 Jazzy robots (rclpy from the pinned PyPI wheels) and a ROS graph to look at, on loopback.

Every process started here, and the test process's own node, keeps discovery on this host with
`ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST` and joins a domain of the test's own (`ROS_DOMAIN_ID`).
"""

from __future__ import annotations

import os
import sys
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import TypeVar

import rclpy
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.signals import SignalHandlerOptions

from testbed.paths import TESTBED
from testbed.processes import RunningProcess, spawn

ROBOT_SCRIPT = TESTBED / "ros2" / "robot.py"
UPDATER_SCRIPT = TESTBED / "ros2" / "updater_robot.py"  # a node that reports as diagnostic_updater does


def ros2_environment(domain: int) -> dict[str, str]:
    """The variables that put a ROS 2 process on `domain`, discovering on this host only."""
    return {"ROS_DOMAIN_ID": str(domain), "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST"}


def start_robot(
    tmp_path: Path, domain: int, *args: str, timeout: float = 30.0, script: Path = ROBOT_SCRIPT
) -> RunningProcess:
    """Start a Jazzy robot (`script`, default `testbed/ros2/robot.py`, with `args`) until it publishes."""
    log_path = tmp_path / f"ros2-robot-{time.monotonic_ns()}.log"
    robot = RunningProcess(
        spawn([sys.executable, str(script), *args], log_path, env=ros2_environment(domain)), log_path
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
def running_robots(
    tmp_path: Path, domain: int, *robots: tuple[str, ...], script: Path = ROBOT_SCRIPT
) -> Iterator[list[RunningProcess]]:
    """Jazzy robots, one per argument tuple, until the block ends (stopped cleanly then)."""
    started: list[RunningProcess] = []
    try:
        for args in robots:
            started.append(start_robot(tmp_path, domain, *args, script=script))
        yield started
    finally:
        for robot in started:
            robot.stop()


T = TypeVar("T")


class Observer:
    """A node of the test process's own, spun by rclpy's executor in a thread.

    It sees the graph and hears topics as any ROS 2 node does, independently of the exporter's code.
    """

    def __init__(self, name: str, domain: int) -> None:
        self._context = Context()
        rclpy.init(context=self._context, domain_id=domain, signal_handler_options=SignalHandlerOptions.NO)
        self.node = Node(name, context=self._context, start_parameter_services=False, enable_rosout=False)
        self._executor = SingleThreadedExecutor(context=self._context)
        self._executor.add_node(self.node)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._spin, name=f"observer-{name}", daemon=True)
        self._thread.start()

    def call(self, function: Callable[[], T]) -> T:
        """`function()`: rclpy's node may be used from any thread while its executor spins."""
        return function()

    def close(self) -> None:
        """Stop spinning and leave the graph."""
        self._stop.set()
        self._thread.join(timeout=10)
        self._executor.shutdown()
        self.node.destroy_node()  # type: ignore[no-untyped-call]
        self._context.try_shutdown()

    def _spin(self) -> None:
        while not self._stop.is_set() and self._context.ok():
            self._executor.spin_once(timeout_sec=0.1)


@contextmanager
def graph_node(domain: int, name: str = "observer") -> Iterator[Observer]:
    """A node of the test process's own in `domain`, on loopback, for the length of the block."""
    previous = {key: os.environ.get(key) for key in ("ROS_AUTOMATIC_DISCOVERY_RANGE",)}
    os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    node = Observer(name, domain)
    try:
        yield node
    finally:
        node.close()
        for key, value in previous.items():
            if value is None:
                os.environ.pop(key, None)
            else:
                os.environ[key] = value
