"""The rclpy transport: the exporter as a ROS 2 node, reading every robot's diagnostics topics raw.

Robots are found in the ROS graph: every topic `<ns>/diagnostics_agg` or `<ns>/diagnostics` of type
`diagnostic_msgs/msg/DiagnosticArray` is robot `<ns>` (the DDS source's naming rules). Each topic gets a
raw subscription, whose bytes go to the same ingest as every transport's (skip-unchanged, the compiled
decoder, the caps). Its QoS follows the topic's publishers: reliable while every one of them is, best-effort
from the first best-effort one on (a reliable subscription never hears it; rclpy says so in an
incompatible-QoS event, and the subscription is made again). Each subscription's matched event tells when
a robot's diagnostics publishers have all left the graph: the robot is down at once, as with Zenoh's
liveliness. Everything runs in the node's executor thread (`node.py`).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field

from diagnostic_msgs.msg import DiagnosticArray
from rclpy.event_handler import SubscriptionEventCallbacks
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.subscription import Subscription
from rclpy.timer import Timer

from overseer.codec import DecodeError, cdr
from overseer.config.ros2 import Ros2Config
from overseer.ingest.payload import PayloadIngest
from overseer.model import FleetModel
from overseer.model.shard import Shard
from overseer.sources.ros2 import node as ros_node
from overseer.sources.topic_names import AGGREGATED, RAW, parse_ros_topic

log = logging.getLogger(__name__)

TRANSPORT = "ros2"
MESSAGE_TYPE = "diagnostic_msgs/msg/DiagnosticArray"
DISCOVERY_PERIOD_SECONDS = 0.5
QUEUE_DEPTH = 10  # a topic's messages between two takes: every node of a robot may publish /diagnostics


def subscription_qos(reliable: bool) -> QoSProfile:
    """ROS's default profile (volatile: it matches transient-local publishers too), reliable or not."""
    return QoSProfile(  # type: ignore[no-untyped-call]
        history=HistoryPolicy.KEEP_LAST,
        depth=QUEUE_DEPTH,
        durability=DurabilityPolicy.VOLATILE,
        reliability=ReliabilityPolicy.RELIABLE if reliable else ReliabilityPolicy.BEST_EFFORT,
    )


@dataclass
class _Feed:
    """One followed topic: its robot, its subscription, and how many publishers it matches now."""

    robot: str
    subscription: Subscription
    reliable: bool
    publishers: int = 0
    ingest: PayloadIngest | None = field(default=None, repr=False)


class Ros2Source:
    """Follows the robots of `shard` in the ROS graph of `config.domain`, as node `node_name`."""

    transport = TRANSPORT

    def __init__(
        self, config: Ros2Config, model: FleetModel, node_name: str, shard: Shard | None = None
    ) -> None:
        """Feed `model`; the node joins the graph on `start`."""
        self._config = config
        self._model = model
        self._node_name = node_name
        self._shard = shard or Shard()
        self._ros: ros_node.RosNode | None = None
        self._feeds: dict[str, _Feed] = {}
        self._robot_topics: dict[str, set[str]] = {}
        self._ignored: set[str] = set()  # topics not ours: another type, another shard, the cap
        self._timer: Timer | None = None

    def start(self) -> None:
        """Join the graph and look for robots every `DISCOVERY_PERIOD_SECONDS` from now on."""
        self._ros = ros_node.acquire(self._node_name, self._config.domain)
        self._ros.call(self._begin)

    def stop(self) -> None:
        """Unsubscribe and leave the graph."""
        ros = self._ros
        if ros is None:
            return
        self._ros = None
        ros_node.leave(ros, self._end)

    @property
    def followed_topics(self) -> dict[str, bool]:
        """Every topic followed now, and whether its subscription is reliable."""
        return {topic: feed.reliable for topic, feed in self._feeds.items()}

    def _begin(self) -> None:
        assert self._ros is not None
        self._timer = self._ros.node.create_timer(DISCOVERY_PERIOD_SECONDS, self._discover)
        self._discover()

    def _end(self) -> None:
        assert self._ros is not None
        node = self._ros.node
        if self._timer is not None:
            node.destroy_timer(self._timer)
        for feed in self._feeds.values():
            node.destroy_subscription(feed.subscription)
        self._feeds.clear()

    def _discover(self) -> None:
        assert self._ros is not None
        for topic, types in self._ros.node.get_topic_names_and_types():
            if topic in self._feeds or topic in self._ignored:
                continue
            parsed = parse_ros_topic(topic)
            if parsed is None or parsed.kind not in self._config.topics:
                continue
            if MESSAGE_TYPE not in types:
                self._ignored.add(topic)
                self._model.count_source_error(TRANSPORT, "unexpected_type")
                log.warning("ignoring %s: type %s, not %s", topic, ", ".join(types), MESSAGE_TYPE)
                continue
            robot = parsed.namespace or self._config.unnamespaced_robot
            if not self._shard.owns(robot):
                self._ignored.add(topic)
                continue
            self._follow(topic, robot, parsed.kind)

    def _follow(self, topic: str, robot: str, kind: str) -> None:
        sibling = topic[: -len(kind)] + (RAW if kind == AGGREGATED else AGGREGATED)
        if self._config.prefer_aggregated and AGGREGATED in self._config.topics:
            if kind == RAW and sibling in self._feeds:
                return
            if kind == AGGREGATED and sibling in self._feeds:
                self._unfollow(sibling)
                self._model.forget_topic(robot, sibling)
        if not self._model.register(robot, TRANSPORT):
            self._ignored.add(topic)
            log.warning("robot cap reached; not following %s", topic)
            return
        self._subscribe(topic, robot, self._publishers_reliable(topic))
        log.info("following robot %s over ROS 2 (%s)", robot, topic)

    def _publishers_reliable(self, topic: str) -> bool:
        assert self._ros is not None
        node = self._ros.node
        publishers = [
            info for info in node.get_publishers_info_by_topic(topic) if info.node_name != node.get_name()
        ]
        return bool(publishers) and all(
            info.qos_profile.reliability == ReliabilityPolicy.RELIABLE for info in publishers
        )

    def _subscribe(self, topic: str, robot: str, reliable: bool) -> None:
        assert self._ros is not None
        previous = self._feeds.get(topic)
        ingest = previous.ingest if previous is not None else None
        if ingest is None:
            ingest = PayloadIngest(self._model, robot, TRANSPORT, topic, cdr.WIRE_FORMAT)

        def on_payload(payload: bytes) -> None:
            try:
                ingest(payload)
            except DecodeError as error:  # counted by the ingest
                log.debug("undecodable message on %s: %s", topic, error)

        events = SubscriptionEventCallbacks(
            matched=lambda status: self._on_matched(topic, status.current_count),  # type: ignore[attr-defined]
            incompatible_qos=lambda _: self._on_incompatible_qos(topic),
            use_default_callbacks=False,
        )
        subscription = self._ros.node.create_subscription(
            DiagnosticArray, topic, on_payload, subscription_qos(reliable), raw=True, event_callbacks=events
        )
        self._feeds[topic] = _Feed(robot, subscription, reliable, 0, ingest)
        self._robot_topics.setdefault(robot, set()).add(topic)

    def _unfollow(self, topic: str) -> None:
        assert self._ros is not None
        feed = self._feeds.pop(topic)
        self._robot_topics[feed.robot].discard(topic)
        self._ros.node.destroy_subscription(feed.subscription)

    def _on_incompatible_qos(self, topic: str) -> None:
        feed = self._feeds.get(topic)
        if feed is None or not feed.reliable:
            return
        log.info("reading %s best-effort, as a publisher of it is", topic)
        self._unfollow(topic)
        self._subscribe(topic, feed.robot, reliable=False)

    def _on_matched(self, topic: str, publishers: int) -> None:
        feed = self._feeds.get(topic)
        if feed is None:
            return
        feed.publishers = publishers
        topics = self._robot_topics.get(feed.robot, ())
        alive = any(self._feeds[other].publishers > 0 for other in topics if other in self._feeds)
        self._model.set_publisher_alive(feed.robot, alive)


def node_name(config: Ros2Config, worker: int, workers: int) -> str:
    """The node an ingest worker (or, with one, the exporter) joins the graph as."""
    return config.node_name if workers == 1 else f"{config.node_name}_ingest_{worker}"
