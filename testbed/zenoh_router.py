"""A Zenoh router for tests: a Python Zenoh session in router mode on one loopback TCP port.

Run as a module (`python -m testbed.zenoh_router PORT [--zenoh-defaults]`); it serves until the process
is stopped. It runs with the router configuration Overseer ships (`deploy/zenoh/router.json5`), listening
on loopback instead; `--zenoh-defaults` leaves Zenoh's own defaults, for benchmarks that compare them.
"""

from __future__ import annotations

import json
import sys
import threading

import zenoh

from testbed.paths import REPO

SHIPPED_CONFIG = REPO / "deploy" / "zenoh" / "router.json5"


def router_config(port: int, zenoh_defaults: bool = False) -> zenoh.Config:
    """The shipped router configuration (or Zenoh's defaults) listening on 127.0.0.1:`port` only."""
    config = zenoh.Config() if zenoh_defaults else zenoh.Config.from_file(str(SHIPPED_CONFIG))
    config.insert_json5("mode", json.dumps("router"))
    config.insert_json5("listen/endpoints", json.dumps([f"tcp/127.0.0.1:{port}"]))
    config.insert_json5("scouting/multicast/enabled", "false")
    return config


def main() -> None:
    """Listen on 127.0.0.1:PORT as a router, multicast scouting off, until the process is stopped."""
    session = zenoh.open(router_config(int(sys.argv[1]), "--zenoh-defaults" in sys.argv[2:]))
    print("ready", session.zid(), flush=True)
    threading.Event().wait()


if __name__ == "__main__":
    main()
