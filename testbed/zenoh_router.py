"""A Zenoh router for tests: a Python Zenoh session in router mode on one loopback TCP port.

Run as a module (`python -m testbed.zenoh_router PORT`); it serves until the process is stopped.
"""

from __future__ import annotations

import json
import sys
import threading

import zenoh


def main() -> None:
    """Listen on 127.0.0.1:PORT as a router, multicast scouting off, until the process is stopped."""
    port = int(sys.argv[1])
    config = zenoh.Config()
    config.insert_json5("mode", json.dumps("router"))
    config.insert_json5("listen/endpoints", json.dumps([f"tcp/127.0.0.1:{port}"]))
    config.insert_json5("scouting/multicast/enabled", "false")
    session = zenoh.open(config)
    print("ready", session.zid(), flush=True)
    threading.Event().wait()


if __name__ == "__main__":
    main()
