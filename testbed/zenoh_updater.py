"""A node on rmw_zenoh that reports as diagnostic_updater does, for robots with no rmw_zenoh on this machine.

rmw_zenoh_cpp is not on PyPI, so this process speaks its wire protocol itself: a liveliness token for the
node (in its namespace) and for its publisher of the absolute `/diagnostics`, samples on the un-namespaced
key `<domain>/diagnostics/<type>/<hash>`, each with the 33-byte attachment whose GID is the hash of the
publisher's token. It behaves as `testbed/ros2/updater_robot.py` does: a start-up array per task with no
hardware_id, then every `--period` all tasks named `<node>: <task>`. Run as a module:
`python -m testbed.zenoh_updater --port 7447 --namespace robot_a --node drive --task 0:motor:ok`.
"""

from __future__ import annotations

import argparse
import json
import signal
import threading
import time

import zenoh

from overseer.codec.cdr import encode_diagnostic_array
from overseer.messages import DiagnosticArray, DiagnosticStatus
from overseer.simulator.zenoh_publisher import attachment
from overseer.sources.zenoh.keys import (
    DIAGNOSTIC_ARRAY_HASH,
    data_key,
    node_token,
    publisher_gid,
    publisher_token,
)


def main() -> None:
    """Report until SIGTERM or SIGINT."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0] if __doc__ else None)
    parser.add_argument("--port", type=int, required=True, help="the router's port on 127.0.0.1")
    parser.add_argument("--domain", type=int, default=0)
    parser.add_argument("--namespace", default="")
    parser.add_argument("--node", default="driver")
    parser.add_argument("--period", type=float, default=1.0)
    parser.add_argument("--hardware-id", default="hw0")
    parser.add_argument("--task", action="append", default=[], help="LEVEL:NAME:MESSAGE")
    parser.add_argument("--late-task", action="append", default=[], help="SECONDS:LEVEL:NAME:MESSAGE")
    parser.add_argument("--token-delay", type=float, default=0.0, help="seconds before the publisher's token")
    args = parser.parse_args()

    config = zenoh.Config()
    config.insert_json5("mode", json.dumps("peer"))
    config.insert_json5("connect/endpoints", json.dumps([f"tcp/127.0.0.1:{args.port}"]))
    config.insert_json5("listen/endpoints", json.dumps(["tcp/127.0.0.1:0"]))
    config.insert_json5("scouting/multicast/enabled", "false")
    session = zenoh.open(config)
    zid = str(session.zid())
    namespace = args.namespace.strip("/")
    # The node is in its namespace; its publisher's topic is the absolute /diagnostics.
    token = publisher_token(
        args.domain, zid, 10, namespace, args.node, "diagnostics", DIAGNOSTIC_ARRAY_HASH, topic_namespace=""
    )
    tokens = [session.liveliness().declare_token(node_token(args.domain, zid, namespace, args.node))]
    if args.token_delay <= 0:
        tokens.append(session.liveliness().declare_token(token))
    publisher = session.declare_publisher(data_key(args.domain, "", "diagnostics"))
    gid = publisher_gid(token)
    sequence = [0]

    def publish(statuses: list[DiagnosticStatus]) -> None:
        sequence[0] += 1
        now = time.time()
        payload = encode_diagnostic_array(DiagnosticArray(int(now), int(now % 1 * 1e9), "", tuple(statuses)))
        publisher.put(payload, attachment=attachment(sequence[0], time.time_ns(), gid))

    tasks: list[tuple[int, str, str]] = []

    def add(spec: str) -> None:
        level, name, message = spec.split(":", 2)
        tasks.append((int(level), name, message))
        publish([DiagnosticStatus(0, f"{args.node}: {name}", "Node starting up", "", ())])

    stop = threading.Event()
    for sig in (signal.SIGTERM, signal.SIGINT):
        signal.signal(sig, lambda *_: stop.set())
    for spec in args.task:
        add(spec)
    late = sorted((float(spec.split(":", 1)[0]), spec.split(":", 1)[1]) for spec in args.late_task)
    print("ready", flush=True)
    started = next_update = time.monotonic()
    updates = 0
    while not stop.wait(0.02):
        if len(tokens) == 1 and time.monotonic() - started >= args.token_delay:
            tokens.append(session.liveliness().declare_token(token))  # a router slow to pass it on, say
        while late and time.monotonic() - started >= late[0][0]:
            add(late.pop(0)[1])
        if time.monotonic() >= next_update:
            updates += 1
            next_update += args.period
            values = (("updates", str(updates)),)
            publish(
                [DiagnosticStatus(lv, f"{args.node}: {n}", m, args.hardware_id, values) for lv, n, m in tasks]
            )
    for declared in tokens:
        declared.undeclare()  # type: ignore[no-untyped-call]
    publisher.undeclare()  # type: ignore[no-untyped-call]
    session.close()  # type: ignore[no-untyped-call]


if __name__ == "__main__":
    main()
