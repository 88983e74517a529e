"""Overseer: fleet-health monitoring for ROS robots."""

__version__ = "0.1.0"
