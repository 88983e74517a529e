"""A real ROS 2 Jazzy robot (rclpy from the pinned PyPI wheels) publishing diagnostic_msgs/DiagnosticArray.

Run with the venv's Python: `robot.py --namespace site_a/robot7 --qos best_effort`. It publishes its
statuses on `/<namespace>/<topic>` at `--rate` Hz from a node of its own (`--node`), prints `ready` once
its publisher exists, and leaves the graph cleanly on SIGTERM (killed with SIGKILL, it just vanishes).
Statuses: `--status LEVEL:NAME:MESSAGE`, repeatable; each carries a `seq` key-value that counts up.
"""

from __future__ import annotations

import argparse
import signal
import threading

import rclpy
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rclpy.executors import SingleThreadedExecutor
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.signals import SignalHandlerOptions


def main() -> None:
    """Publish until SIGTERM or SIGINT."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0] if __doc__ else None)
    parser.add_argument("--namespace", default="")
    parser.add_argument("--topic", default="diagnostics_agg", choices=["diagnostics_agg", "diagnostics"])
    parser.add_argument("--node", default="diagnostic_aggregator")
    parser.add_argument("--qos", default="reliable", choices=["reliable", "best_effort"])
    parser.add_argument("--durability", default="volatile", choices=["volatile", "transient_local"])
    parser.add_argument("--rate", type=float, default=2.0)
    parser.add_argument("--status", action="append", default=[], help="LEVEL:NAME:MESSAGE")
    args = parser.parse_args()
    statuses = [text.split(":", 2) for text in args.status] or [["0", "/Power/Battery", "OK"]]

    rclpy.init(signal_handler_options=SignalHandlerOptions.NO)
    namespace = "/" + args.namespace.strip("/") if args.namespace.strip("/") else None
    node = rclpy.create_node(args.node, namespace=namespace)
    qos = QoSProfile(  # type: ignore[no-untyped-call]
        history=HistoryPolicy.KEEP_LAST,
        depth=10,
        reliability=ReliabilityPolicy.RELIABLE if args.qos == "reliable" else ReliabilityPolicy.BEST_EFFORT,
        durability=DurabilityPolicy.VOLATILE
        if args.durability == "volatile"
        else DurabilityPolicy.TRANSIENT_LOCAL,
    )
    publisher = node.create_publisher(DiagnosticArray, args.topic, qos)  # relative: inside the namespace
    sequence = [0]

    def publish() -> None:
        sequence[0] += 1
        message = DiagnosticArray()
        message.header.stamp = node.get_clock().now().to_msg()
        message.status = [
            DiagnosticStatus(
                level=bytes([int(level)]),
                name=name,
                message=text,
                hardware_id=args.node,
                values=[KeyValue(key="seq", value=str(sequence[0]))],
            )
            for level, name, text in statuses
        ]
        publisher.publish(message)

    node.create_timer(1.0 / args.rate, publish)
    stop = threading.Event()
    for sig in (signal.SIGTERM, signal.SIGINT):
        signal.signal(sig, lambda *_: stop.set())
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    print("ready", flush=True)
    while not stop.is_set():
        executor.spin_once(timeout_sec=0.1)
    node.destroy_node()  # type: ignore[no-untyped-call]
    rclpy.shutdown()


if __name__ == "__main__":
    main()
