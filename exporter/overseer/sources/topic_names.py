"""Mapping between ROS 2 diagnostics topics, DDS topic names and robot names."""

from __future__ import annotations

from typing import NamedTuple

ROS_TOPIC_PREFIX = "rt/"
AGGREGATED = "diagnostics_agg"
RAW = "diagnostics"


class DiagnosticsTopic(NamedTuple):
    """A diagnostics topic split into the robot's namespace ('' when none) and its kind."""

    namespace: str
    kind: str


def parse_dds_topic(dds_topic: str) -> DiagnosticsTopic | None:
    """Split `rt/<ns>/diagnostics_agg` or `rt/<ns>/diagnostics`; None for any other topic.

    Nested namespaces are kept whole: `rt/site_a/robot7/diagnostics_agg` is robot `site_a/robot7`.
    """
    if not dds_topic.startswith(ROS_TOPIC_PREFIX):
        return None
    namespace, _, kind = dds_topic[len(ROS_TOPIC_PREFIX) :].rpartition("/")
    if kind not in (AGGREGATED, RAW):
        return None
    if namespace.startswith("/") or namespace.endswith("/") or "//" in namespace:
        return None
    return DiagnosticsTopic(namespace, kind)


def dds_topic_name(namespace: str, kind: str) -> str:
    """The DDS topic carrying ROS topic `/<namespace>/<kind>`."""
    namespace = namespace.strip("/")
    return f"{ROS_TOPIC_PREFIX}{namespace}/{kind}" if namespace else f"{ROS_TOPIC_PREFIX}{kind}"


def parse_ros_topic(ros_topic: str) -> DiagnosticsTopic | None:
    """Split ROS topic `/<ns>/diagnostics_agg` or `/<ns>/diagnostics`, as `parse_dds_topic` its DDS name."""
    return parse_dds_topic(ROS_TOPIC_PREFIX + ros_topic[1:]) if ros_topic.startswith("/") else None
