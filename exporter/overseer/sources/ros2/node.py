"""The process's ROS 2 node: an rclpy context of its own, one node, one executor thread that does it all.

Every rclpy call on the node runs in the executor's thread: the source's discovery timer, its raw
subscriptions' callbacks and their matched events, and whatever another thread hands over with `call`.
The executor is rclpy's EventsExecutor (no wait set rebuilt for every wake-up: about 5 % of a core for
1,000 subscriptions at 1 Hz, against a whole core for the SingleThreadedExecutor), driven by `spin_once`
(its `spin` busy-loops in rclpy 7.1.6). A source and the fleet publisher of one process share the node.
"""

from __future__ import annotations

import atexit
import logging
import queue
import threading
from collections.abc import Callable
from concurrent.futures import Future
from typing import Any, TypeVar

import rclpy
from rclpy.context import Context
from rclpy.experimental.events_executor import EventsExecutor
from rclpy.node import Node
from rclpy.signals import SignalHandlerOptions

log = logging.getLogger(__name__)

SPIN_TIMEOUT_SECONDS = 0.25
CALLS_PERIOD_SECONDS = 0.05  # how often the executor looks for calls from other threads (it has no guard
# conditions to be woken by: a timer does it, for a few microseconds twenty times a second)
T = TypeVar("T")


class RosNode:
    """One rclpy node in a context of its own, spun by an executor thread; started by `acquire`."""

    def __init__(self, name: str, domain: int) -> None:
        """Join ROS domain `domain` as node `name`: rclpy's signal handlers stay off (the exporter's own)."""
        self.name = name
        self.domain = domain
        self.context = Context()
        rclpy.init(context=self.context, domain_id=domain, signal_handler_options=SignalHandlerOptions.NO)
        self.node = Node(name, context=self.context, start_parameter_services=False, enable_rosout=False)
        self._executor = EventsExecutor(context=self.context)
        self._executor.add_node(self.node)
        self._calls: queue.SimpleQueue[tuple[Callable[[], Any], Future[Any]]] = queue.SimpleQueue()
        self._calls_timer = self.node.create_timer(CALLS_PERIOD_SECONDS, self._run_calls)
        self._stopping = threading.Event()
        self._thread = threading.Thread(target=self._spin, name=f"ros2-{name}", daemon=True)
        self._thread.start()

    def call(self, function: Callable[[], T], timeout: float = 30.0) -> T:
        """Run `function` in the executor's thread and return what it returns (or raise what it raises)."""
        if threading.current_thread() is self._thread:
            return function()
        done: Future[T] = Future()
        self._calls.put((function, done))
        return done.result(timeout)

    def close(self) -> None:
        """Stop spinning, leave the graph and shut the context down."""
        self._stopping.set()
        self._thread.join(timeout=10)
        self._executor.shutdown()
        self.node.destroy_node()  # type: ignore[no-untyped-call]
        self.context.try_shutdown()

    def _run_calls(self) -> None:
        while True:
            try:
                function, done = self._calls.get_nowait()
            except queue.Empty:
                return
            if done.set_running_or_notify_cancel():
                try:
                    done.set_result(function())
                except Exception as error:  # handed to the caller
                    done.set_exception(error)

    def _spin(self) -> None:
        while not self._stopping.is_set() and self.context.ok():
            try:
                self._executor.spin_once(timeout_sec=SPIN_TIMEOUT_SECONDS)
            except Exception:  # one failing callback must not end the node
                log.exception("ROS 2 executor callback failed")


_lock = threading.Lock()
_nodes: dict[tuple[str, int], tuple[RosNode, int]] = {}


def acquire(name: str, domain: int) -> RosNode:
    """The process's node `name` on `domain`, started on first use; `release` it when done."""
    with _lock:
        node, users = _nodes.get((name, domain), (None, 0))
        if node is None:
            node = RosNode(name, domain)
            log.info("joined ROS 2 domain %d as node %s", domain, name)
        _nodes[(name, domain)] = (node, users + 1)
        return node


@atexit.register
def _close_all() -> None:
    """Close the nodes still open at exit: a thread still spinning then would abort the interpreter."""
    with _lock:
        open_nodes = [node for node, _ in _nodes.values()]
        _nodes.clear()
    for node in open_nodes:
        node.close()


def leave(node: RosNode, end: Callable[[], None]) -> None:
    """Run `end` (a user's clean-up of its entities) on the node's thread, then `release` the node."""
    try:
        node.call(end)
    finally:
        release(node)


def release(node: RosNode) -> None:
    """One user less of `node`; the last one closes it."""
    with _lock:
        held, users = _nodes[(node.name, node.domain)]
        if users > 1:
            _nodes[(node.name, node.domain)] = (held, users - 1)
            return
        del _nodes[(node.name, node.domain)]
    node.close()
