"""Which robot a diagnostics message belongs to: its topic's namespace, its domain's name, or its node's.

ROS 2's diagnostic_updater (Python and C++) and the aggregator publish on the absolute `/diagnostics` and
`/diagnostics_agg` whatever their node's namespace, so robots that share a domain under namespaces all
publish on one topic. The rules, in order:

1. A topic with a namespace (`/robot_a/diagnostics`) is robot `robot_a`, as it always was.
2. On a domain given a `robot_name`, every un-namespaced topic is that one robot.
3. Otherwise an un-namespaced topic's message belongs to the namespace of the node that published it:
   the first `namespace_depth` segments of it (`/robot_a/drivers/lidar` is `robot_a` with the default 1;
   0 keeps the whole namespace). A node without a namespace falls back to `domain<ID>`.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

from overseer.config.fleet import DEFAULT_NAMESPACE_DEPTH

# What a ROS 2 name token may hold; a namespace read off the network is checked against it.
_TOKEN = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")


@dataclass(frozen=True)
class RobotNaming:
    """The naming rules of one domain: its robot for un-namespaced topics, and how nodes name robots."""

    unnamespaced_robot: str
    named: bool = False  # the domain was given a robot_name: it is one robot
    namespace_depth: int = DEFAULT_NAMESPACE_DEPTH

    def of_topic(self, topic_namespace: str) -> str | None:
        """The robot a topic's namespace decides, or None when its publisher's node decides."""
        if topic_namespace:
            return topic_namespace
        return self.unnamespaced_robot if self.named else None

    def of_node(self, node_namespace: str) -> str | None:
        """The robot a node's namespace names; the domain's for the root; None for an invalid namespace."""
        tokens = [token for token in node_namespace.split("/") if token]
        if not tokens:
            return self.unnamespaced_robot
        if not node_namespace.startswith("/") or not all(_TOKEN.fullmatch(token) for token in tokens):
            return None
        if self.namespace_depth:
            tokens = tokens[: self.namespace_depth]
        return "/".join(tokens)
