"""The fleet simulator through rclpy: every virtual robot publishes from a real ROS 2 Jazzy node.

One node (`simulated_fleet`) of one rclpy context holds a publisher per robot on `/<ns>/diagnostics_agg`
(or `/diagnostics`), of type diagnostic_msgs/msg/DiagnosticArray, with ROS's default QoS or best-effort.
The payload is the same CDR the DDS simulator writes, handed to rclpy serialized. Publications of one
round are spread over most of the period, as real robots are not in step.
"""

from __future__ import annotations

import os

from diagnostic_msgs.msg import DiagnosticArray as RosDiagnosticArray
from rclpy.publisher import Publisher
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

from overseer.simulator.publisher import FleetSimulator, SimulatedRobot, SimulatorSettings
from overseer.sources.ros2 import node as ros_node

NODE_NAME = "simulated_fleet"


class Ros2FleetSimulator(FleetSimulator):
    """Publishes the virtual fleet through rclpy instead of Cyclone DDS."""

    def __init__(self, settings: SimulatorSettings, best_effort: bool = False) -> None:
        """Build the fleet and join the ROS graph of `settings.domain` (on loopback when it says so)."""
        if settings.separate_domains:
            raise ValueError("--separate-domains is not supported over ROS 2: one node joins one domain")
        super().__init__(settings)
        if settings.loopback_only:
            os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"  # read by the RMW as the node starts
        self._ros = ros_node.acquire(NODE_NAME, settings.domain)
        self._qos = QoSProfile(  # type: ignore[no-untyped-call]
            history=HistoryPolicy.KEEP_LAST,
            depth=10,
            durability=DurabilityPolicy.VOLATILE,
            reliability=ReliabilityPolicy.BEST_EFFORT if best_effort else ReliabilityPolicy.RELIABLE,
        )
        self._publishers: dict[str, Publisher] = {}

    def ros_topic(self, robot: SimulatedRobot) -> str:
        """The ROS topic the robot publishes on."""
        return f"/{robot.name.strip('/')}/{self.settings.topic}"

    def publish_once(self) -> int:
        """Publish every running robot's diagnostics once; returns the number of messages written."""
        now, stamp = self.stamp_now()
        written = 0
        for robot in self.paced_robots():
            publisher = self._publishers.get(robot.name)
            if publisher is None:
                continue
            publisher.publish(self.payload(robot, now, stamp))
            written += 1
        self.published += written
        return written

    def every_robot_subscribed(self) -> bool:
        """Whether every robot's publisher has `settings.subscribers` subscriptions."""
        wanted = self.settings.subscribers
        return all(publisher.get_subscription_count() >= wanted for publisher in self._publishers.values())

    def close(self) -> None:
        """Destroy every publisher and leave the graph."""
        for robot in self.robots:
            self._close_writer(robot)
        ros_node.release(self._ros)

    def _open_writer(self, robot: SimulatedRobot) -> None:
        if not robot.running or robot.name in self._publishers:
            return
        topic = self.ros_topic(robot)
        self._publishers[robot.name] = self._ros.call(
            lambda: self._ros.node.create_publisher(RosDiagnosticArray, topic, self._qos)
        )

    def _close_writer(self, robot: SimulatedRobot) -> None:
        publisher = self._publishers.pop(robot.name, None)
        if publisher is not None:
            self._ros.call(lambda: self._ros.node.destroy_publisher(publisher))
