"""The process's ROS 2 node: an rclpy context of its own, one node, and one thread that does its work.

No executor spins the node: the source takes its subscriptions' messages through rcl as they arrive
(`rcl_take.py`), so nothing here waits on a wait set. The node's thread runs what the node's users ask
of it, in order: calls handed over from other threads (`call`) and periodic tasks (`every`: the source's
look at the graph, the fleet publisher's array). Every rclpy call on the node runs in that thread. A
source and the fleet publisher of one process share the node.
"""

from __future__ import annotations

import atexit
import heapq
import itertools
import logging
import queue
import threading
import time
from collections.abc import Callable
from concurrent.futures import Future
from typing import Any, TypeVar

import rclpy
from rclpy.context import Context
from rclpy.node import Node
from rclpy.signals import SignalHandlerOptions

log = logging.getLogger(__name__)

IDLE_WAIT_SECONDS = 0.25
T = TypeVar("T")


class RosNode:
    """One rclpy node in a context of its own, and the thread that runs its work; started by `acquire`."""

    def __init__(self, name: str, domain: int) -> None:
        """Join ROS domain `domain` as node `name`: rclpy's signal handlers stay off (the exporter's own)."""
        self.name = name
        self.domain = domain
        self.context = Context()
        rclpy.init(context=self.context, domain_id=domain, signal_handler_options=SignalHandlerOptions.NO)
        self.node = Node(name, context=self.context, start_parameter_services=False, enable_rosout=False)
        self._calls: queue.SimpleQueue[tuple[Callable[[], Any], Future[Any]] | None] = queue.SimpleQueue()
        self._tasks: list[tuple[float, int, float, Callable[[], None]]] = []  # (due, id, period, task)
        self._cancelled: set[int] = set()
        self._ids = itertools.count()
        self._stopping = threading.Event()
        self._thread = threading.Thread(target=self._run, name=f"ros2-{name}", daemon=True)
        self._thread.start()

    def call(self, function: Callable[[], T], timeout: float = 30.0) -> T:
        """Run `function` in the node's thread and return what it returns (or raise what it raises)."""
        if threading.current_thread() is self._thread:
            return function()
        done: Future[T] = Future()
        self._calls.put((function, done))
        try:
            return done.result(timeout)
        finally:
            del done  # what it raises holds this frame in its traceback: a cycle while this frame holds it

    def every(self, period: float, task: Callable[[], None]) -> int:
        """Run `task` in the node's thread every `period` seconds from now on; an id for `cancel`."""
        task_id = next(self._ids)
        self.call(lambda: heapq.heappush(self._tasks, (time.monotonic() + period, task_id, period, task)))
        return task_id

    def cancel(self, task_id: int) -> None:
        """Run the task `every` returned `task_id` for no more."""
        self.call(lambda: self._cancelled.add(task_id))

    def close(self) -> None:
        """Stop the thread, leave the graph and shut the context down."""
        self._stopping.set()
        self._calls.put(None)
        self._thread.join(timeout=10)
        self.node.destroy_node()  # type: ignore[no-untyped-call]
        self.context.try_shutdown()

    def _run(self) -> None:
        while not self._stopping.is_set():
            wait = IDLE_WAIT_SECONDS
            if self._tasks:
                wait = min(wait, max(0.0, self._tasks[0][0] - time.monotonic()))
            try:
                item = self._calls.get(timeout=wait)
            except queue.Empty:
                item = None
            if item is not None:
                function, done = item
                if done.set_running_or_notify_cancel():
                    try:
                        done.set_result(function())
                    except Exception as error:  # handed to the caller
                        done.set_exception(error)
            self._run_due_tasks()

    def _run_due_tasks(self) -> None:
        now = time.monotonic()
        while self._tasks and self._tasks[0][0] <= now and not self._stopping.is_set():
            _, task_id, period, task = heapq.heappop(self._tasks)
            if task_id in self._cancelled:
                self._cancelled.discard(task_id)
                continue
            try:
                task()
            except Exception:  # one failing task must not end the node's work
                log.exception("ROS 2 node task failed")
            heapq.heappush(self._tasks, (max(now, time.monotonic()) + period, task_id, period, task))


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
    """Close the nodes still open at exit, so that each leaves the graph cleanly."""
    with _lock:
        open_nodes = [node for node, _ in _nodes.values()]
        _nodes.clear()
    for node in open_nodes:
        node.close()


def leave(node: RosNode, end: Callable[[RosNode], None]) -> None:
    """Run `end(node)` (a user's clean-up of its entities) on the node's thread, then `release` the node."""
    try:
        node.call(lambda: end(node))
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
