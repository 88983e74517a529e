"""`overseer simulate`: the paper's virtual robots, publishing real wire traffic over DDS, Zenoh or rclpy."""

from __future__ import annotations

import argparse
import re
import signal
from typing import TYPE_CHECKING

from overseer.commands import Command
from overseer.config import ConfigError
from overseer.config.dds import parse_dds_peer
from overseer.log_format import configure_logging

if TYPE_CHECKING:
    from overseer.simulator.publisher import FleetSimulator, SimulatorSettings

_ROS_NAMESPACE = re.compile(r"[A-Za-z_][A-Za-z0-9_]*(/[A-Za-z_][A-Za-z0-9_]*)*")
_TYPE_HASH = re.compile(r"[A-Za-z0-9_]+")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The fleet's shape, how it publishes, and the scripted events."""
    parser.add_argument("--robots", type=int, default=3, help="number of robots (default 3)")
    parser.add_argument("--components", type=int, default=10, help="leaf components per robot (default 10)")
    parser.add_argument("--warn", type=int, default=1, help="components in WARN per robot (default 1)")
    parser.add_argument("--error", type=int, default=1, help="components in ERROR per robot (default 1)")
    parser.add_argument("--rate", type=float, default=1.0, help="publications per second (default 1)")
    parser.add_argument("--domain", type=int, default=0, help="DDS domain (default 0)")
    parser.add_argument(
        "--separate-domains",
        action="store_true",
        help="put robot I on domain DOMAIN+I-1 with no namespace instead of namespaces",
    )
    parser.add_argument("--namespace-prefix", default="robot", help="robot names are PREFIX1..PREFIXN")
    parser.add_argument("--topic", choices=["diagnostics_agg", "diagnostics"], default="diagnostics_agg")
    parser.add_argument("--dds.loopback-only", dest="loopback_only", action="store_true")
    parser.add_argument(
        "--dds.peer",
        dest="dds_peers",
        action="append",
        default=[],
        metavar="HOST[:PORT]",
        help="send DDS discovery to this host directly, e.g. the exporter's (networks without multicast)",
    )
    parser.add_argument(
        "--transport",
        choices=["dds", "zenoh", "ros2"],
        default="dds",
        help="publish over DDS (Cyclone), Zenoh, or through rclpy as ROS 2 nodes do (default dds)",
    )
    parser.add_argument(
        "--ros2.qos",
        dest="ros2_qos",
        choices=["reliable", "best_effort"],
        default="reliable",
        help="with --transport ros2: the publishers' reliability (default reliable, as ROS's default)",
    )
    parser.add_argument(
        "--zenoh.connect",
        dest="zenoh_connect",
        action="append",
        metavar="ENDPOINT",
        help="a Zenoh router or peer to connect to, e.g. tcp/router.example:7447; repeat for several",
    )
    parser.add_argument(
        "--zenoh.listen",
        dest="zenoh_listen",
        action="append",
        metavar="ENDPOINT",
        help="a Zenoh endpoint to listen on, e.g. tcp/0.0.0.0:7447; repeat for several",
    )
    parser.add_argument(
        "--zenoh.mode",
        dest="zenoh_mode",
        choices=["client", "peer"],
        help="Zenoh session mode (default peer)",
    )
    parser.add_argument(
        "--zenoh.bridge-keys",
        dest="zenoh_bridge_keys",
        action="store_true",
        help="publish as zenoh-bridge-ros2dds does (<ns>/diagnostics_agg) instead of as rmw_zenoh",
    )
    parser.add_argument(
        "--zenoh.type-hash",
        dest="zenoh_type_hash",
        metavar="RIHS01_…",
        help="type hash in the rmw_zenoh keys (default: DiagnosticArray's in Jazzy)",
    )
    parser.add_argument(
        "--vary-values",
        nargs="?",
        const="battery",
        default="none",
        choices=("none", "battery", "all"),
        help="change values at every publication: each robot's battery voltage (battery, the default "
        "without a word), or a value of every status (all)",
    )
    parser.add_argument(
        "--wait-for-subscribers",
        type=float,
        default=0.0,
        metavar="SECONDS",
        help="before publishing, wait up to SECONDS until every robot has a subscriber (benchmarks)",
    )
    parser.add_argument(
        "--subscribers",
        type=int,
        default=1,
        metavar="N",
        help="with --wait-for-subscribers: wait for N subscribers of each robot (exporters compared)",
    )
    parser.add_argument("--duration", type=float, help="stop after this many seconds")
    parser.add_argument(
        "--event",
        action="append",
        default=[],
        metavar="T:ROBOT[:COMPONENT]:ACTION",
        help="scripted change, e.g. '5:robot1:/Power/Robot Battery:ERROR' or '10:robot2:stop'",
    )
    parser.add_argument("--log.level", dest="log_level", default="info")


def settings_of(args: argparse.Namespace) -> SimulatorSettings:
    """The simulation the arguments ask for; ConfigError naming the first bad argument."""
    from overseer.simulator.publisher import EventError, SimulatorSettings, parse_event

    try:
        events = [parse_event(text) for text in args.event]
    except EventError as error:
        raise ConfigError(str(error)) from None
    for name in ("robots", "components"):
        if getattr(args, name) < 1:
            raise ConfigError(f"--{name}: must be at least 1, got {getattr(args, name)}")
    if args.warn < 0 or args.error < 0 or args.warn + args.error > args.components:
        raise ConfigError(
            f"--warn and --error: need 0 <= warn + error <= components, got {args.warn} + {args.error}"
        )
    if not _ROS_NAMESPACE.fullmatch(args.namespace_prefix):
        raise ConfigError(
            "--namespace-prefix: expected ROS name tokens (letters, digits, _ and /), "
            f"got {args.namespace_prefix!r}"
        )
    if not args.rate > 0:
        raise ConfigError(f"--rate: must be positive, got {args.rate}")
    peers = tuple(parse_dds_peer(text, "--dds.peer") for text in args.dds_peers)
    if args.loopback_only and not all(peer.is_loopback for peer in peers):
        raise ConfigError("--dds.peer: only loopback peers go with --dds.loopback-only")
    return SimulatorSettings(
        robots=args.robots,
        components=args.components,
        warn=args.warn,
        error=args.error,
        rate=args.rate,
        domain=args.domain,
        separate_domains=args.separate_domains,
        namespace_prefix=args.namespace_prefix,
        topic=args.topic,
        loopback_only=args.loopback_only,
        peers=peers,
        vary_values=args.vary_values,
        wait_for_subscribers=args.wait_for_subscribers,
        subscribers=args.subscribers,
        events=events,
    )


def simulator_of(args: argparse.Namespace, settings: SimulatorSettings) -> FleetSimulator:
    """The simulator of the transport asked for; ConfigError when it cannot be made."""
    from overseer.simulator.publisher import EventError, FleetSimulator

    try:
        if args.transport == "dds":
            return FleetSimulator(settings)
        if args.transport == "zenoh":
            return _zenoh_simulator(args, settings)
        from overseer.sources.ros2 import require_rclpy

        require_rclpy("--transport ros2")
        from overseer.simulator.ros2_publisher import Ros2FleetSimulator

        return Ros2FleetSimulator(settings, best_effort=args.ros2_qos == "best_effort")
    except (EventError, ValueError) as error:
        raise ConfigError(str(error)) from None


def _zenoh_simulator(args: argparse.Namespace, settings: SimulatorSettings) -> FleetSimulator:
    """The simulator publishing over Zenoh, as rmw_zenoh or as zenoh-bridge-ros2dds does."""
    from overseer.simulator.zenoh_publisher import ZenohFleetSimulator, ZenohSettings
    from overseer.sources.zenoh.keys import DIAGNOSTIC_ARRAY_HASH

    type_hash = args.zenoh_type_hash or DIAGNOSTIC_ARRAY_HASH
    if not _TYPE_HASH.fullmatch(type_hash):
        raise ConfigError(f"--zenoh.type-hash: expected letters, digits and _, got {type_hash!r}")
    zenoh_settings = ZenohSettings(
        connect=tuple(args.zenoh_connect or ()),
        listen=tuple(args.zenoh_listen or ()),
        mode=args.zenoh_mode or "peer",
        bridge_keys=args.zenoh_bridge_keys,
        type_hash=type_hash,
    )
    try:
        return ZenohFleetSimulator(settings, zenoh_settings)
    except Exception as error:  # zenoh.ZError: an endpoint Zenoh refuses, a router a client cannot reach
        raise ConfigError(f"--zenoh.*: cannot open the Zenoh session: {error}") from None


def run(args: argparse.Namespace) -> int:
    """Publish until SIGTERM, SIGINT or `--duration`."""
    settings = settings_of(args)
    configure_logging(args.log_level)
    simulator = simulator_of(args, settings)
    for sig in (signal.SIGTERM, signal.SIGINT):
        signal.signal(sig, lambda *_: simulator.stop())
    where = f"DDS domain {settings.domain}"
    if args.transport == "ros2":
        where = f"ROS 2 domain {settings.domain} through rclpy ({args.ros2_qos})"
    if args.transport == "zenoh":
        where = (
            f"Zenoh ({'bridge keys' if args.zenoh_bridge_keys else f'rmw_zenoh, domain {settings.domain}'})"
        )
    print(
        f"simulating {settings.robots} robots x {settings.components} components at {settings.rate:g} Hz "
        f"on {where}",
        flush=True,
    )
    simulator.run(args.duration)
    print(f"published {simulator.published} messages", flush=True)
    return 0


COMMAND = Command(
    "simulate",
    "publish a virtual fleet's diagnostics over DDS, Zenoh or rclpy",
    "The paper's virtual robots: a fleet whose components report OK, WARN and ERROR as scripted, "
    "published as real robots publish.",
    add_arguments,
    run,
)
