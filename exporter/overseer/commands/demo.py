"""`overseer demo`: the exporter and a simulated fleet together on loopback, with a few scripted incidents."""

from __future__ import annotations

import argparse
import logging
import threading
import time

from overseer.commands import Command
from overseer.commands.signals import StopSignals
from overseer.config import load_config
from overseer.config.web import DEFAULT_PORT
from overseer.garbage_collection import collect_in_large_batches
from overseer.heap_trim import shape_heap, trim_heap_every
from overseer.log_format import configure_logging

log = logging.getLogger("overseer")

# The demo fleet: robot1 all OK, robot4 only warnings, the rest as simulated; then a few incidents.
DEMO_SCRIPT = (
    "0:robot1:/Laser/Laser2:OK",
    "0:robot1:/Camera/Cam2:OK",
    "0:robot4:/Laser/Laser2:OK",
    "20:robot1:/Temp/Sensor1:ERROR",
    "40:robot1:/Temp/Sensor1:OK",
    "30:robot3:stop",
    "60:robot3:start",
)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Where to serve, the demo's DDS domain and the fleet's size."""
    parser.add_argument("--web.listen-address", dest="listen_address", default=f"127.0.0.1:{DEFAULT_PORT}")
    parser.add_argument("--domain", type=int, default=42, help="DDS domain of the demo (default 42)")
    parser.add_argument("--robots", type=int, default=6)
    parser.add_argument("--components", type=int, default=10)
    parser.add_argument("--log.level", dest="log_level", default="info")


def run(args: argparse.Namespace) -> int:
    """Run the demo until SIGTERM or SIGINT."""
    collect_in_large_batches()
    shape_heap()
    trim_heap_every()
    config = load_config(
        None,
        {
            "web.listen_address": args.listen_address,
            "dds.domains": [args.domain],
            "dds.loopback_only": True,
            "log_level": args.log_level,
        },
    )
    configure_logging(config.log_level)
    from overseer.app import Exporter
    from overseer.simulator.publisher import FleetSimulator, SimulatorSettings, parse_event

    exporter = Exporter(config)
    signals = StopSignals()  # before its parts start: a stop meanwhile waits for them
    exporter.start()
    robots = {f"robot{index}" for index in range(1, args.robots + 1)}
    settings = SimulatorSettings(
        robots=args.robots,
        components=args.components,
        warn=1,
        error=1,
        domain=args.domain,
        loopback_only=True,
        events=[event for event in map(parse_event, DEMO_SCRIPT) if event.robot in robots],
    )
    simulator = FleetSimulator(settings)
    thread = threading.Thread(target=simulator.run, name="simulator", daemon=True)
    thread.start()
    url = exporter.server.url
    print(
        f"Overseer demo: {settings.robots} simulated robots on DDS domain {args.domain} (loopback only)\n"
        f"  status page  {url}/\n  metrics      {url}/metrics\n  JSON API     {url}/api/v1/robots\n"
        "Scripted: robot1 /Temp/Sensor1 ERROR at 20 s (OK at 40 s), robot3 stops at 30 s, back at 60 s.\n"
        "Press Ctrl-C to stop.",
        flush=True,
    )
    started = time.monotonic()
    signals.wait()
    simulator.stop()
    thread.join(timeout=5)
    exporter.stop()
    log.info("demo ran for %.0fs", time.monotonic() - started)
    return 0


COMMAND = Command(
    "demo",
    "run the exporter and a simulated fleet together on loopback",
    "The exporter and six simulated robots on DDS over loopback, with incidents scripted at 20, 30, 40 "
    "and 60 s: the status page, /metrics and the API to look at.",
    add_arguments,
    run,
)
