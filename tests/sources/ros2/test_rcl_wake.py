"""rcl wakes the ROS 2 source without Python: the middleware's receive thread never waits for the GIL.

A Python callback there froze the exporter: rclpy holds the GIL in `create_subscription`, which waited
for the receive thread, which waited for the GIL to run the callback.
"""

from __future__ import annotations

import ctypes
import os
import time
from pathlib import Path

import pytest
from diagnostic_msgs.msg import DiagnosticArray

from overseer.sources.ros2 import node as ros_node
from overseer.sources.ros2.rcl_take import wake_on_new_message
from overseer.sources.ros2.source import subscription_qos
from testbed.ros2 import running_robots

pytestmark = pytest.mark.servers  # real ROS 2 nodes on loopback

RATE = 50.0  # the robot's arrays a second
HOLD_SECONDS = 1.0


def hold_the_gil(seconds: float) -> None:
    """Sleep in C without releasing the GIL, as rclpy's bindings do in their calls to the middleware."""
    ctypes.PyDLL(None).usleep(int(seconds * 1e6))


def test_the_middleware_wakes_a_subscription_while_another_thread_holds_the_gil(
    tmp_path: Path, dds_domain: int, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    robot = ("--namespace", "robot1", "--rate", f"{RATE:g}", "--status", "0:/Power:ok")
    with running_robots(tmp_path, dds_domain, robot):
        ros = ros_node.acquire("wake_test", dds_domain)
        wake = os.eventfd(0, os.EFD_NONBLOCK | os.EFD_CLOEXEC)
        subscription = ros.call(
            lambda: ros.node.create_subscription(
                DiagnosticArray, "/robot1/diagnostics_agg", lambda _: None, subscription_qos(True), raw=True
            )
        )
        try:
            ros.call(lambda: wake_on_new_message(subscription.handle.pointer, wake))
            deadline = time.monotonic() + 30
            while time.monotonic() < deadline:
                try:
                    if os.eventfd_read(wake) > 0:
                        break
                except BlockingIOError:
                    time.sleep(0.05)
            else:
                pytest.fail("the robot's arrays never woke the subscription")
            hold_the_gil(HOLD_SECONDS)
            woken = os.eventfd_read(wake)  # what arrived while no other thread could run Python
        finally:
            ros.call(lambda: wake_on_new_message(subscription.handle.pointer, None))
            ros.call(lambda: ros.node.destroy_subscription(subscription))
            os.close(wake)
            ros_node.release(ros)
    assert woken >= RATE * HOLD_SECONDS / 2, f"{woken} arrays counted in {HOLD_SECONDS:g} s at {RATE:g} Hz"
