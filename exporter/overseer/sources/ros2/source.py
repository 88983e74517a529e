"""The rclpy transport: the exporter as a ROS 2 node, reading every robot's diagnostics topics raw.

Robots are found in the ROS graph: every topic `<ns>/diagnostics_agg` or `<ns>/diagnostics` of type
`diagnostic_msgs/msg/DiagnosticArray` is robot `<ns>` (the DDS source's naming rules, `robot_naming.py`).
A message on an un-namespaced topic (diagnostic_updater publishes on the absolute `/diagnostics` whatever
its node's namespace) belongs to the robot its publisher's node names: rcl tells each message's publisher
GID (`rcl_take.py`), the graph each publisher's node. Each publisher is a feed of its robot, whose bytes go
to the same ingest as every transport's (skip-unchanged, the compiled decoder, the caps). A publisher whose
node the graph has not told within a grace is the domain's robot's until the graph tells it
(`reattribution.py`).

A topic's subscription is reliable while every publisher of it is, best-effort from the first best-effort
one on (a reliable subscription never hears it). The graph also tells when a robot's diagnostics
publishers have all left: the robot is down at once, as with Zenoh's liveliness. Graph work runs in the
node's thread (`node.py`); messages are taken in a thread of the source's own, woken through an eventfd
per subscription that rcl writes to as messages arrive (`rcl_take.py`).
"""

from __future__ import annotations

import contextlib
import logging
import os
import select
import threading
import time
from dataclasses import dataclass, field

from diagnostic_msgs.msg import DiagnosticArray
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.subscription import Subscription

from overseer.codec import DecodeError, cdr
from overseer.config.fleet import DEFAULT_NAMESPACE_DEPTH
from overseer.config.ros2 import Ros2Config
from overseer.ingest.payload import PayloadIngest
from overseer.model import FleetModel
from overseer.model.shard import Shard
from overseer.sources.reattribution import MovedFeeds
from overseer.sources.robot_naming import RobotNaming
from overseer.sources.ros2 import node as ros_node
from overseer.sources.ros2.rcl_take import RawTaker, wake_on_new_message
from overseer.sources.topic_names import AGGREGATED, RAW, parse_ros_topic

log = logging.getLogger(__name__)

TRANSPORT = "ros2"
MESSAGE_TYPE = "diagnostic_msgs/msg/DiagnosticArray"
DISCOVERY_PERIOD_SECONDS = 0.5
# A publisher whose node the graph does not tell by then is the domain's robot's: a little more than Fast
# DDS's heartbeat period (3 s), at which a reader that matched after a node's graph was written hears it.
ATTRIBUTION_GRACE_SECONDS = 4.0
# How long a publisher taken for the domain's robot is looked up in the graph at every discovery (each a
# lookup of its topic's publishers); later, only when the topic's publishers change.
REATTRIBUTION_WINDOW_SECONDS = 60.0
MAX_PENDING_MESSAGES = 16  # per publisher, while its robot is not known yet
QUEUE_DEPTH = 10  # a topic's messages between two takes: every node of a robot may publish /diagnostics
# What rclpy says of a publisher's node before its participant's graph has told it: unknown when the graph
# lists the participant but not the publisher, a bare DDS application when it lists nothing of it as yet.
_UNKNOWN_NAMESPACES = frozenset({"_NODE_NAMESPACE_UNKNOWN_", "_CREATED_BY_BARE_DDS_APP_"})


def subscription_qos(reliable: bool) -> QoSProfile:
    """ROS's default profile (volatile: it matches transient-local publishers too), reliable or not."""
    return QoSProfile(  # type: ignore[no-untyped-call]
        history=HistoryPolicy.KEEP_LAST,
        depth=QUEUE_DEPTH,
        durability=DurabilityPolicy.VOLATILE,
        reliability=ReliabilityPolicy.RELIABLE if reliable else ReliabilityPolicy.BEST_EFFORT,
    )


@dataclass
class _Publisher:
    """One publisher of a followed topic: its robot once known, and the ingest of its feed."""

    gid: bytes
    robot: str | None
    seen_at: float  # monotonic
    in_graph: bool = False  # adopted from the graph, which then tells when it leaves
    by_domain: bool = False  # the domain's robot's, as its node was not in the graph within the grace
    ingest: PayloadIngest | None = None
    ignored: bool = False  # another worker's robot, the robot cap, or raw beside aggregated
    pending: list[bytes] = field(default_factory=list)


@dataclass
class _Topic:
    """One followed topic: its subscription, and the publishers heard on it or seen in the graph."""

    name: str
    kind: str
    robot: str | None  # None: an un-namespaced topic, whose publishers' nodes name their robots
    subscription: Subscription
    reliable: bool
    wake: int  # the eventfd rcl adds the number of new messages to
    publishers: dict[bytes, _Publisher] = field(default_factory=dict)
    graph_count: int = -1  # publishers in the graph at the last look
    dirty: bool = True  # look up its publishers in the graph at the next discovery


def _new_eventfd() -> int:
    """A counter the take thread can wait on: read without blocking, closed on exec."""
    return os.eventfd(0, os.EFD_NONBLOCK | os.EFD_CLOEXEC)


class Ros2Source:
    """Follows the robots of `shard` in the ROS graph of `config.domain`, as node `node_name`."""

    transport = TRANSPORT

    def __init__(
        self,
        config: Ros2Config,
        model: FleetModel,
        node_name: str,
        shard: Shard | None = None,
        namespace_depth: int = DEFAULT_NAMESPACE_DEPTH,
    ) -> None:
        """Feed `model`; the node joins the graph on `start`."""
        self._config = config
        self._model = model
        self._node_name = node_name
        self._shard = shard or Shard()
        self._naming = RobotNaming(config.unnamespaced_robot, config.robot_name is not None, namespace_depth)
        self._ros: ros_node.RosNode | None = None
        self._task: int | None = None
        self._topics: dict[str, _Topic] = {}
        self._ignored: set[str] = set()  # topics not ours: another type, another shard, the cap
        self._lock = threading.Lock()  # publishers' pending messages and ingests, between the two threads
        self._taking = threading.Lock()  # held while messages are taken: a subscription goes only between
        self._poll: select.epoll | None = None  # every topic's wake-up eventfd, and `_stopping`, once started
        self._stopping = -1
        self._woken: dict[int, _Topic] = {}  # wake-up eventfd → its topic, changed under `_taking`
        self._taker: threading.Thread | None = None
        self._robot_publishers: dict[str, set[tuple[str, bytes]]] = {}  # robot → (topic, gid) it is heard on
        self._aggregated: set[str] = set()  # robots read from diagnostics_agg only
        self._moved = MovedFeeds(model)

    def start(self) -> None:
        """Join the graph, take messages as they arrive, and look for robots every period from now on."""
        self._ros = ros_node.acquire(self._node_name, self._config.domain)
        poll, stopping = select.epoll(), _new_eventfd()
        poll.register(stopping, select.EPOLLIN)
        self._poll, self._stopping = poll, stopping
        self._taker = threading.Thread(
            target=self._take_loop, args=(poll, stopping), name="ros2-take", daemon=True
        )
        self._taker.start()
        self._ros.call(self._discover)
        self._task = self._ros.every(DISCOVERY_PERIOD_SECONDS, self._discover)

    def stop(self) -> None:
        """Unsubscribe and leave the graph."""
        ros, self._ros = self._ros, None
        if ros is None:
            return
        ros_node.leave(ros, self._end)
        os.eventfd_write(self._stopping, 1)
        if self._taker is not None:
            self._taker.join(timeout=5)
        if (self._taker is None or not self._taker.is_alive()) and self._poll is not None:
            self._poll.close()
            os.close(self._stopping)
            self._poll, self._stopping = None, -1

    @property
    def followed_topics(self) -> dict[str, bool]:
        """Every topic followed now, and whether its subscription is reliable."""
        return {name: topic.reliable for name, topic in self._topics.items()}

    def _end(self, ros: ros_node.RosNode) -> None:
        if self._task is not None:
            ros.cancel(self._task)
        for name in list(self._topics):
            self._unfollow(ros, name)

    def _discover(self) -> None:
        ros = self._ros
        if ros is None:
            return
        self._moved.forget(self._robot_publishers.__contains__)
        node = ros.node
        for name, types in node.get_topic_names_and_types():
            if name in self._topics or name in self._ignored:
                continue
            parsed = parse_ros_topic(name)
            if parsed is None or parsed.kind not in self._config.topics:
                continue
            if MESSAGE_TYPE not in types:
                self._ignored.add(name)
                self._model.count_source_error(TRANSPORT, "unexpected_type")
                log.warning("ignoring %s: type %s, not %s", name, ", ".join(types), MESSAGE_TYPE)
                continue
            robot = self._naming.of_topic(parsed.namespace)
            if robot is not None and not self._shard.owns(robot):
                self._ignored.add(name)
                continue
            if robot is not None and parsed.kind == RAW and self._prefers_aggregated(name, parsed.kind):
                continue  # a namespaced robot's raw topic is not even read beside its aggregator's
            self._follow(ros, name, parsed.kind, robot)
        recent = time.monotonic() - REATTRIBUTION_WINDOW_SECONDS
        for topic in list(self._topics.values()):
            count = node.count_publishers(topic.name)
            unknown = any(
                publisher.robot is None or (publisher.by_domain and publisher.seen_at > recent)
                for publisher in topic.publishers.values()
            )
            if count != topic.graph_count or topic.dirty or unknown:
                topic.graph_count = count
                topic.dirty = False
                self._look_up_publishers(ros, topic)

    def _prefers_aggregated(self, topic: str, kind: str) -> bool:
        preferred = self._config.prefer_aggregated and AGGREGATED in self._config.topics
        return preferred and topic[: -len(kind)] + AGGREGATED in self._topics

    def _follow(self, ros: ros_node.RosNode, name: str, kind: str, robot: str | None) -> None:
        if robot is not None and kind == AGGREGATED and self._config.prefer_aggregated:
            sibling = name[: -len(kind)] + RAW
            if sibling in self._topics:
                self._unfollow(ros, sibling)
        self._subscribe(ros, name, kind, robot, reliable=True)
        log.info("following %s over ROS 2", name)

    def _subscribe(
        self, ros: ros_node.RosNode, name: str, kind: str, robot: str | None, reliable: bool
    ) -> None:
        subscription = ros.node.create_subscription(
            DiagnosticArray, name, lambda _: None, subscription_qos(reliable), raw=True
        )
        previous = self._topics.get(name)
        topic = _Topic(name, kind, robot, subscription, reliable, _new_eventfd())
        if previous is not None:
            topic.publishers = previous.publishers
        self._topics[name] = topic
        with self._taking:
            self._woken[topic.wake] = topic
        assert self._poll is not None, "topics are followed only once started"
        self._poll.register(topic.wake, select.EPOLLIN)
        wake_on_new_message(subscription.handle.pointer, topic.wake)
        os.eventfd_write(topic.wake, 1)  # what arrived before the wake-up was set

    def _unfollow(self, ros: ros_node.RosNode, name: str) -> None:
        topic = self._topics.pop(name)
        with self._taking:
            wake_on_new_message(topic.subscription.handle.pointer, None)
            ros.node.destroy_subscription(topic.subscription)
            del self._woken[topic.wake]
            if self._poll is not None:
                self._poll.unregister(topic.wake)
            os.close(topic.wake)

    def _look_up_publishers(self, ros: ros_node.RosNode, topic: _Topic) -> None:
        """The topic's publishers in the graph: their QoS, their nodes, and which have left.

        A publisher's node names the robot of an un-namespaced topic.
        """
        node = ros.node
        own = node.get_name()
        infos = [info for info in node.get_publishers_info_by_topic(topic.name) if info.node_name != own]
        best_effort = ReliabilityPolicy.BEST_EFFORT
        if topic.reliable and any(info.qos_profile.reliability == best_effort for info in infos):
            log.info("reading %s best-effort, as a publisher of it is", topic.name)
            self._unfollow(ros, topic.name)
            self._subscribe(ros, topic.name, topic.kind, topic.robot, reliable=False)
            topic = self._topics[topic.name]
        now = time.monotonic()
        in_graph: dict[bytes, str | None] = {}
        for info in infos:
            gid = bytes(info.endpoint_gid)
            robot = topic.robot
            if robot is None and info.node_namespace not in _UNKNOWN_NAMESPACES:
                robot = self._naming.of_node(info.node_namespace)
                if robot is None:
                    self._model.count_source_error(TRANSPORT, "invalid_namespace")
                    robot = self._naming.unnamespaced_robot
            in_graph[gid] = robot
        for gid, robot in in_graph.items():
            with self._lock:
                publisher = topic.publishers.setdefault(gid, _Publisher(gid, None, now))
            if publisher.robot is not None:
                publisher.in_graph = True  # heard first, adopted: the graph now tells when it leaves
            if robot is None:
                continue
            if publisher.robot is None:
                publisher.in_graph = True
                self._adopt(topic, publisher, robot)
            elif publisher.by_domain:  # its node is told at last
                publisher.by_domain, publisher.in_graph = False, True
                if robot != publisher.robot:
                    self._move(topic, publisher, robot)
        for gid, publisher in list(topic.publishers.items()):
            if publisher.robot is None and now - publisher.seen_at >= ATTRIBUTION_GRACE_SECONDS:
                # Heard, or in the graph with no node told as yet; in the graph, it tells when it leaves.
                publisher.by_domain, publisher.in_graph = True, gid in in_graph
                self._adopt(topic, publisher, self._naming.unnamespaced_robot)
            elif gid in in_graph:
                continue
            elif publisher.in_graph:
                with self._lock:
                    del topic.publishers[gid]
                self._publisher_left(topic, publisher)

    def _adopt(self, topic: _Topic, publisher: _Publisher, robot: str) -> None:
        """Follow `publisher` as a feed of `robot` (when this source follows the robot), its pending first.

        Only the node's thread adopts, so what it keeps of robots needs no lock.
        """
        publisher.robot = robot
        self._robot_publishers.setdefault(robot, set()).add((topic.name, publisher.gid))
        if not self._shard.owns(robot):
            publisher.ignored = True
        elif topic.kind == RAW and robot in self._aggregated:
            publisher.ignored = True  # the robot's aggregator says it all
        elif not self._model.register(robot, TRANSPORT):
            publisher.ignored = True
            log.warning("robot cap reached; not following robot %s (%s)", robot, topic.name)
        if publisher.ignored:
            with self._lock:
                publisher.pending.clear()
            return
        if topic.kind == AGGREGATED and self._config.prefer_aggregated and robot not in self._aggregated:
            self._aggregated.add(robot)
            self._ignore_raw(robot)
        feed = _feed_name(topic, publisher)
        ingest = PayloadIngest(self._model, robot, TRANSPORT, topic.name, cdr.WIRE_FORMAT, feed)
        while True:  # what arrived meanwhile, in order, before new messages go straight to the ingest
            with self._lock:
                pending, publisher.pending = publisher.pending, []
                if not pending:
                    publisher.ingest = ingest
                    break
            for payload in pending:
                _ingest(ingest, payload, topic.name)
        log.info("following robot %s over ROS 2 (%s, publisher %s)", robot, topic.name, publisher.gid.hex())

    def _move(self, topic: _Topic, publisher: _Publisher, robot: str) -> None:
        """Follow a publisher taken for its domain's robot as a feed of `robot`, its node's."""
        old = publisher.robot
        assert old is not None
        with self._lock:  # what arrives from now on waits in `pending` for the new ingest
            followed, publisher.ingest, publisher.ignored = publisher.ingest is not None, None, False
        self._drop_publisher(old, topic, publisher)
        if followed:
            self._moved.moved(old, _feed_name(topic, publisher))
        log.info(
            "publisher %s of %s: a node of robot %s, not %s", publisher.gid.hex(), topic.name, robot, old
        )
        self._adopt(topic, publisher, robot)

    def _ignore_raw(self, robot: str) -> None:
        """Leave a robot's raw diagnostics publishers once it has an aggregator: forget what they said."""
        for topic in self._topics.values():
            if topic.kind != RAW:
                continue
            for publisher in topic.publishers.values():
                if publisher.robot == robot and not publisher.ignored:
                    publisher.ignored, publisher.ingest = True, None
                    self._model.forget_topic(robot, topic.name)

    def _publisher_left(self, topic: _Topic, publisher: _Publisher) -> None:
        robot = publisher.robot
        assert robot is not None
        if self._drop_publisher(robot, topic, publisher) and self._shard.owns(robot):
            self._model.publisher_left(robot)
            log.info("robot %s: its last diagnostics publisher left the graph", robot)

    def _drop_publisher(self, robot: str, topic: _Topic, publisher: _Publisher) -> bool:
        """`publisher` of `topic` is no longer one of `robot`'s; True when it was its last."""
        publishers = self._robot_publishers.get(robot, set())
        publishers.discard((topic.name, publisher.gid))
        if publishers:
            return False
        self._robot_publishers.pop(robot, None)
        return True

    def _take_loop(self, poll: select.epoll, stopping: int) -> None:
        taker = RawTaker()
        try:
            while True:
                for wake, _ in poll.poll():  # the GIL is released while it waits
                    if wake == stopping:
                        return
                    with self._taking:
                        topic = self._woken.get(wake)
                        if topic is None:  # unfollowed since it woke
                            continue
                        # Messages arriving from now on wake it again. Nothing to read: the wake-up was
                        # of a topic unfollowed since, whose eventfd's number a new topic's has taken.
                        with contextlib.suppress(BlockingIOError):
                            os.eventfd_read(topic.wake)
                        address = topic.subscription.handle.pointer
                        while (message := taker.take(address)) is not None:
                            self._on_message(topic, message.payload, message.publisher_gid)
        except Exception:  # the thread ends; the source says why
            log.exception("taking ROS 2 messages failed")
        finally:
            taker.close()

    def _on_message(self, topic: _Topic, payload: bytes, gid: bytes) -> None:
        with self._lock:
            publisher = topic.publishers.get(gid)
            if publisher is None:  # a publisher the graph has not shown yet: the next discovery adopts it
                publisher = topic.publishers[gid] = _Publisher(gid, None, time.monotonic())
                topic.dirty = True
            ingest = publisher.ingest
            if ingest is None:
                if not publisher.ignored:
                    if len(publisher.pending) < MAX_PENDING_MESSAGES:
                        publisher.pending.append(payload)
                    else:
                        publisher.pending[-1] = payload  # the newest says the most
                return
        _ingest(ingest, payload, topic.name)


def _feed_name(topic: _Topic, publisher: _Publisher) -> str:
    """The feed a publisher's messages are of in the model: one per publisher of a topic."""
    return f"{topic.name}@{publisher.gid.hex()}"


def _ingest(ingest: PayloadIngest, payload: bytes, topic: str) -> None:
    try:
        ingest(payload)
    except DecodeError as error:  # counted by the ingest
        log.debug("undecodable message on %s: %s", topic, error)


def node_name(config: Ros2Config, worker: int, workers: int) -> str:
    """The node an ingest worker (or, with one, the exporter) joins the graph as."""
    return config.node_name if workers == 1 else f"{config.node_name}_ingest_{worker}"
