"""A ROS 2 Jazzy node that reports its diagnostics the way ros/diagnostics' `diagnostic_updater` does.

Run with the venv's Python. What a real updater does, and so this node:
- it publishes on the absolute topic `/diagnostics` whatever its own namespace (the aggregator likewise
  on `/diagnostics_agg`: `--topic diagnostics_agg`), reliable with a history of one (`--qos` may make it
  best-effort, as some drivers are);
- each status is named `<node name>: <task name>` (`--fqn`: the node's full name);
- adding a task publishes at once a one-status array for it alone: OK, "Node starting up", and an empty
  hardware_id, whatever hardware_id the node has set;
- every `--period` seconds (diagnostic_updater.period, 1 s by default) it publishes one array of all its
  tasks, each with the node's hardware_id;
- `--bare` leaves the node name out of the status names, as ntp_monitor and other hand-written
  monitors do.

Tasks: `--task LEVEL:NAME:MESSAGE` at start, `--late-task SECONDS:LEVEL:NAME:MESSAGE` added that long
after the first array. It prints `ready` once its publisher exists and leaves the graph cleanly on
SIGTERM or SIGINT.
"""

from __future__ import annotations

import argparse
import signal
import threading
import time

import rclpy
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.signals import SignalHandlerOptions


class Task:
    """One diagnostic task: its name and what it reports."""

    def __init__(self, spec: str) -> None:
        level, self.name, self.message = spec.split(":", 2)
        self.level = int(level)


class Reporter:
    """The updater's part of a node: its tasks, its hardware_id and its publisher."""

    def __init__(self, node: Node, args: argparse.Namespace) -> None:
        self._node = node
        self._prefix = "" if args.bare else (node.get_fully_qualified_name() if args.fqn else node.get_name())
        qos = QoSProfile(  # type: ignore[no-untyped-call]
            history=HistoryPolicy.KEEP_LAST,
            depth=1,
            reliability=ReliabilityPolicy.RELIABLE
            if args.qos == "reliable"
            else ReliabilityPolicy.BEST_EFFORT,
            durability=DurabilityPolicy.VOLATILE,
        )
        self._publisher = node.create_publisher(DiagnosticArray, "/" + args.topic, qos)
        self._hardware_id = args.hardware_id
        self._tasks: list[Task] = []
        self._updates = 0

    def add(self, task: Task) -> None:
        """Take a task on, and say at once that it is starting up (with no hardware_id)."""
        self._tasks.append(task)
        self._publish([self._status(task.name, 0, "Node starting up", "")])

    def update(self) -> None:
        """Report every task, each with the node's hardware_id and a counter that moves."""
        self._updates += 1
        statuses = [
            self._status(task.name, task.level, task.message, self._hardware_id) for task in self._tasks
        ]
        for status in statuses:
            status.values = [KeyValue(key="updates", value=str(self._updates))]
        self._publish(statuses)

    def _status(self, task: str, level: int, message: str, hardware_id: str) -> DiagnosticStatus:
        name = f"{self._prefix}: {task}" if self._prefix else task
        return DiagnosticStatus(level=bytes([level]), name=name, message=message, hardware_id=hardware_id)

    def _publish(self, statuses: list[DiagnosticStatus]) -> None:
        array = DiagnosticArray()
        array.header.stamp = self._node.get_clock().now().to_msg()
        array.status = statuses
        self._publisher.publish(array)


def main() -> None:
    """Report until SIGTERM or SIGINT."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0] if __doc__ else None)
    parser.add_argument("--namespace", default="")
    parser.add_argument("--node", default="driver")
    parser.add_argument("--topic", default="diagnostics", choices=["diagnostics", "diagnostics_agg"])
    parser.add_argument("--qos", default="reliable", choices=["reliable", "best_effort"])
    parser.add_argument("--period", type=float, default=1.0)
    parser.add_argument("--hardware-id", default="hw0")
    parser.add_argument("--fqn", action="store_true")
    parser.add_argument("--bare", action="store_true")
    parser.add_argument("--task", action="append", default=[], help="LEVEL:NAME:MESSAGE")
    parser.add_argument("--late-task", action="append", default=[], help="SECONDS:LEVEL:NAME:MESSAGE")
    args = parser.parse_args()

    rclpy.init(signal_handler_options=SignalHandlerOptions.NO)
    namespace = "/" + args.namespace.strip("/") if args.namespace.strip("/") else None
    node = rclpy.create_node(args.node, namespace=namespace)
    reporter = Reporter(node, args)
    for spec in args.task:
        reporter.add(Task(spec))
    late = sorted((float(spec.split(":", 1)[0]), Task(spec.split(":", 1)[1])) for spec in args.late_task)
    node.create_timer(args.period, reporter.update)
    stop = threading.Event()
    for sig in (signal.SIGTERM, signal.SIGINT):
        signal.signal(sig, lambda *_: stop.set())
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    print("ready", flush=True)
    started = time.monotonic()
    while not stop.is_set():
        executor.spin_once(timeout_sec=0.05)
        while late and time.monotonic() - started >= late[0][0]:
            reporter.add(late.pop(0)[1])
    node.destroy_node()  # type: ignore[no-untyped-call]
    rclpy.shutdown()


if __name__ == "__main__":
    main()
