#!/usr/bin/python3
"""A rospy node publishing a fixed DiagnosticArray at a steady rate, as a diagnostic aggregator does.

Run by /usr/bin/python3 with ROS_MASTER_URI (and ROS_IP) set, never by the project's venv:
  diagnostics_publisher.py --node aggregator --rate 2 \
      --status 'OK:/Power/Battery:Charged:bms:voltage=12.6,percent=93' --status 'ERROR:/Laser:No scans'
Each --status is LEVEL:NAME[:MESSAGE[:HARDWARE_ID[:KEY=VALUE,...]]] with LEVEL OK, WARN, ERROR, STALE
or a number.
"""

from __future__ import annotations

import argparse
from typing import Any

import rospy
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue

LEVELS = {"OK": 0, "WARN": 1, "ERROR": 2, "STALE": 3}


def parse_status(text: str) -> Any:
    """The DiagnosticStatus described by one --status argument."""
    level, name, message, hardware_id, values = [*text.split(":", 4), "", "", ""][:5]
    number = LEVELS[level] if level in LEVELS else int(level)
    pairs = [item.partition("=") for item in values.split(",") if item]
    return DiagnosticStatus(
        level=number - 256 if number > 127 else number,
        name=name,
        message=message,
        hardware_id=hardware_id,
        values=[KeyValue(key=key, value=value) for key, _, value in pairs],
    )


def main() -> None:
    """Publish until shut down."""
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    parser.add_argument("--node", default="diagnostic_aggregator", help="the node's name")
    parser.add_argument("--topic", default="/diagnostics_agg")
    parser.add_argument("--rate", type=float, default=1.0, help="messages per second")
    parser.add_argument("--status", action="append", default=[], help="a component; repeat for several")
    args = parser.parse_args(rospy.myargv()[1:])
    statuses = [parse_status(text) for text in args.status]
    rospy.init_node(args.node)
    publisher = rospy.Publisher(args.topic, DiagnosticArray, queue_size=10)
    rate = rospy.Rate(args.rate)
    print(f"publishing {len(statuses)} statuses on {args.topic} at {args.rate:g} Hz", flush=True)
    while not rospy.is_shutdown():
        array = DiagnosticArray(status=statuses)
        array.header.stamp = rospy.Time.now()
        publisher.publish(array)
        try:
            rate.sleep()
        except rospy.ROSInterruptException:
            break


if __name__ == "__main__":
    main()
