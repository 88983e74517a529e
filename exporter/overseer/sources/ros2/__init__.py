"""ROS 2 robots through rclpy: the exporter as a ROS 2 node on whatever RMW the installation has."""

from __future__ import annotations

import importlib

from overseer.config import ConfigError


def require_rclpy(what: str) -> None:
    """ConfigError naming `what` when rclpy or diagnostic_msgs cannot be imported (the ros2 extra)."""
    try:
        importlib.import_module("rclpy")
        importlib.import_module("diagnostic_msgs.msg")
    except ImportError as error:
        raise ConfigError(
            f"{what} needs rclpy and diagnostic_msgs: install them with pip install 'overseer[ros2]', or run "
            f"on a ROS 2 host's Python ({error})"
        ) from None
