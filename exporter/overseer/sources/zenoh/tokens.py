"""Whose diagnostics publisher a liveliness token announces: its topic, its GID and its robot."""

from __future__ import annotations

from typing import NamedTuple

from overseer.config.zenoh import ZenohConfig
from overseer.sources.robot_naming import RobotNaming
from overseer.sources.zenoh.keys import DiagnosticsKey, parse_bridge_token, parse_publisher


class TokenSubject(NamedTuple):
    """The publisher a token announces: its topic, its GID (b"" for the bridge's) and its robot."""

    topic: DiagnosticsKey
    gid: bytes
    robot: str | None  # None when the node's namespace is not a valid ROS name


def token_subject(key: str, config: ZenohConfig, naming: RobotNaming) -> TokenSubject | None:
    """The diagnostics publisher an rmw_zenoh or bridge token announces; None for any other token.

    The robot is the topic's namespace, or the publishing node's (diagnostic_updater publishes on the
    un-namespaced `/diagnostics`); a bridge's un-namespaced topic is the domain's robot.
    """
    publisher = parse_publisher(key, config.domain)
    if publisher is not None:
        topic = publisher.topic
        robot = naming.of_topic(topic.namespace)
        if robot is None:
            robot = naming.of_node(publisher.node_namespace)
        return TokenSubject(topic, publisher.gid, robot)
    bridged = parse_bridge_token(key)
    if bridged is None:
        return None
    return TokenSubject(bridged, b"", bridged.namespace or config.unnamespaced_robot)
