"""The `overseer` command: `run` the exporter, `simulate` a fleet, a loopback `demo`, `maintenance`."""

from __future__ import annotations

import argparse
import logging
import os
import re
import signal
import sys
import threading
import time
from collections.abc import Iterable, Sequence
from typing import Any

from overseer import __version__
from overseer.config import ConfigError, load_config
from overseer.config.dds import parse_dds_peer
from overseer.config.events import parse_max_size
from overseer.config.parsers import parse_duration
from overseer.config.web import DEFAULT_PORT
from overseer.log_format import configure_logging
from overseer.maintenance_command import add_maintenance_parser, run_maintenance

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

_ROS_NAMESPACE = re.compile(r"[A-Za-z_][A-Za-z0-9_]*(/[A-Za-z_][A-Za-z0-9_]*)*")


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the `overseer` console script."""
    parser = _parser()
    args = parser.parse_args(argv)
    if args.command is None:
        parser.print_help()
        return 2
    handler: Any = {"run": _run, "simulate": _simulate, "demo": _demo, "maintenance": run_maintenance}[
        args.command
    ]
    try:
        return int(handler(args))
    except ConfigError as error:
        print(f"overseer {args.command}: configuration error: {error}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        return 0


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="overseer", description=__doc__)
    parser.add_argument("--version", action="version", version=f"overseer {__version__}")
    commands = parser.add_subparsers(dest="command", metavar="COMMAND")

    run = commands.add_parser("run", help="run the exporter", description="Serve the fleet's diagnostics.")
    run.add_argument("--config.file", dest="config_file", metavar="PATH", help="YAML configuration file")
    _add_exporter_flags(run)

    simulate = commands.add_parser("simulate", help="publish a virtual fleet's diagnostics over DDS")
    _add_simulator_flags(simulate)

    demo = commands.add_parser("demo", help="run the exporter and a simulated fleet together on loopback")
    demo.add_argument("--web.listen-address", dest="listen_address", default=f"127.0.0.1:{DEFAULT_PORT}")
    demo.add_argument("--domain", type=int, default=42, help="DDS domain of the demo (default 42)")
    demo.add_argument("--robots", type=int, default=6)
    demo.add_argument("--components", type=int, default=10)
    demo.add_argument("--log.level", dest="log_level", default="info")
    add_maintenance_parser(commands)
    return parser


def _add_exporter_flags(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--web.listen-address",
        dest="listen_address",
        metavar="HOST:PORT",
        help=f"address to serve on (default :{DEFAULT_PORT})",
    )
    parser.add_argument(
        "--web.config.file",
        dest="web_config_file",
        metavar="PATH",
        help="exporter-toolkit web config: TLS, client certificates, basic auth (default: plain HTTP)",
    )
    parser.add_argument(
        "--dds.domain",
        dest="domains",
        type=int,
        action="append",
        metavar="ID",
        help="DDS domain to join; repeat for several (default 0)",
    )
    parser.add_argument(
        "--dds.loopback-only",
        dest="loopback_only",
        action="store_true",
        default=None,
        help="keep DDS traffic on the loopback interface (tests, demos)",
    )
    parser.add_argument(
        "--dds.cyclonedds-uri",
        dest="cyclonedds_uri",
        metavar="URI",
        help="Cyclone DDS configuration (XML or file://)",
    )
    parser.add_argument(
        "--dds.peer",
        dest="dds_peers",
        action="append",
        metavar="HOST[:PORT]",
        help="send DDS discovery to this host directly (networks without multicast); repeat for several",
    )
    parser.add_argument(
        "--dds.max-participant-index",
        dest="max_participant_index",
        type=int,
        metavar="N",
        help="probe participant indices 0..N (DDS processes) on each peer without a port (default 32)",
    )
    parser.add_argument(
        "--ros1.robot",
        dest="ros1_robots",
        action="append",
        metavar="NAME=MASTER_URI",
        help="a ROS 1 robot by its master, e.g. robot1=http://10.0.0.5:11311; repeat for several",
    )
    parser.add_argument(
        "--ros-master",
        dest="ros_masters",
        action="append",
        metavar="URL",
        help="a ROS 1 robot by its master alone, named after the master's host (http://10.0.0.5:11311 is "
        "robot 10.0.0.5; with one master, --ros1.robot NAME names it); repeat for several",
    )
    parser.add_argument(
        "--web.external-url",
        dest="external_url",
        metavar="URL",
        help="the URL users reach this exporter at, for links to the status page in alerts",
    )
    parser.add_argument(
        "--web.enable-maintenance-api",
        dest="enable_maintenance_api",
        action="store_true",
        help="let the users of maintenance.writers open and end maintenance windows (POST, DELETE "
        "/api/v1/maintenance); reading is always on",
    )
    parser.add_argument(
        "--dds.disabled",
        dest="dds_disabled",
        action="store_true",
        help="do not join DDS (with Zenoh or ROS 1 only)",
    )
    _add_zenoh_flags(parser, exporter=True)
    _add_ros2_flags(parser)
    parser.add_argument(
        "--shard",
        metavar="I/N",
        help="follow only the robots whose name hashes to shard I of N (default 0/1)",
    )
    parser.add_argument(
        "--ingest.workers",
        dest="ingest_workers",
        metavar="N",
        help="worker processes sharing the ingest, each following its own robots "
        "(default: one per core, at most 16; 1 ingests in the exporter's process)",
    )
    parser.add_argument("--fleet.stale-after", dest="stale_after", metavar="DURATION")
    parser.add_argument("--fleet.robot-timeout", dest="robot_timeout", metavar="DURATION")
    parser.add_argument("--fleet.expire-after", dest="expire_after", metavar="DURATION")
    parser.add_argument(
        "--fleet.robot-namespace-depth",
        dest="robot_namespace_depth",
        type=int,
        metavar="N",
        help="leading segments of a node's namespace that name its robot, for un-namespaced topics "
        "(default 1: /robot_a/drivers is robot_a; 0: the whole namespace)",
    )
    parser.add_argument("--log.level", dest="log_level", choices=["debug", "info", "warning", "error"])
    parser.add_argument(
        "--log.format", dest="log_format", choices=["text", "json"], help="log lines as text or JSON"
    )
    parser.add_argument(
        "--events.path", dest="events_path", metavar="PATH", help="event history database (SQLite)"
    )
    parser.add_argument("--events.retention", dest="events_retention", metavar="DURATION")
    parser.add_argument("--events.max-size", dest="events_max_size", metavar="SIZE")
    _add_icinga2_flags(parser)


def _add_ros2_flags(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--ros2",
        dest="ros2",
        action="store_true",
        help="join the robots' ROS 2 graph as a node through rclpy (pip install overseer[ros2]); the DDS "
        "source is then off unless the configuration turns it on",
    )
    parser.add_argument("--ros2.node-name", dest="ros2_node_name", metavar="NAME", help="default overseer")
    parser.add_argument(
        "--ros2.domain", dest="ros2_domain", metavar="ID", type=int, help="default ROS_DOMAIN_ID, else 0"
    )
    parser.add_argument(
        "--ros2.fleet-topic",
        dest="ros2_fleet_topic",
        metavar="TOPIC",
        help="where the fleet's DiagnosticArray is published (default /overseer/fleet_diagnostics)",
    )


def _ros2_overrides(args: argparse.Namespace) -> dict[str, Any]:
    """The `ros2.*` keys given as flags; any of them turns the ROS 2 transport on."""
    enabled: dict[str, Any] = {"ros2.enabled": True} if args.ros2 else {}
    return enabled | _given_flags(args, "ros2", ("node_name", "domain", "fleet_topic"))


def _given_flags(args: argparse.Namespace, section: str, keys: Iterable[str]) -> dict[str, Any]:
    """`section.key` for each of the keys whose flag (`--section.key`) was given."""
    values = {key: getattr(args, f"{section}_{key}", None) for key in keys}
    return {f"{section}.{key}": value for key, value in values.items() if value is not None}


def _add_icinga2_flags(parser: argparse.ArgumentParser) -> None:
    for flag, metavar, text in _ICINGA2_FLAGS:
        dest = f"icinga2_{flag.replace('-', '_')}"
        parser.add_argument(f"--icinga2.{flag}", dest=dest, metavar=metavar, help=text)


_ICINGA2_FLAGS = (
    ("url", "URL", "push to this Icinga 2 API, e.g. https://icinga.example:5665 (see docs/nagios-icinga.md)"),
    ("username", "NAME", "Icinga 2 ApiUser"),
    ("password-file", "PATH", "file whose first line is the ApiUser's password"),
    ("ca-file", "PATH", "CA certificate of the Icinga 2 API"),
    ("tls-server-name", "NAME", "name in the Icinga 2 API's certificate, when not the URL's host"),
    ("client-cert", "PATH", "client certificate instead of a password"),
    ("client-key", "PATH", "the client certificate's key"),
    ("interval", "DURATION", "push every robot's results this often, and at once on a change (default 60s)"),
)


def _add_zenoh_flags(parser: argparse.ArgumentParser, exporter: bool) -> None:
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
        help="Zenoh session mode (default client)",
    )
    if not exporter:
        return
    parser.add_argument(
        "--zenoh.domain",
        dest="zenoh_domain",
        type=int,
        metavar="N",
        help="ROS domain of rmw_zenoh keys (default 0)",
    )
    parser.add_argument(
        "--zenoh.config",
        dest="zenoh_config",
        metavar="FILE",
        help="native Zenoh JSON5 configuration (TLS, mTLS, access control)",
    )


def _add_simulator_flags(parser: argparse.ArgumentParser) -> None:
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
    _add_zenoh_flags(parser, exporter=False)
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


def _exporter_overrides(args: argparse.Namespace) -> dict[str, Any]:
    overrides: dict[str, Any] = {}
    if args.listen_address is not None:
        overrides["web.listen_address"] = args.listen_address
    if args.web_config_file is not None:
        overrides["web.config_file"] = args.web_config_file
    if args.domains:
        overrides["dds.domains"] = list(args.domains)
    if args.loopback_only:
        overrides["dds.loopback_only"] = True
    if args.cyclonedds_uri:
        overrides["dds.cyclonedds_uri"] = args.cyclonedds_uri
    if args.dds_peers:
        overrides["dds.peers"] = list(args.dds_peers)
    if args.max_participant_index is not None:
        overrides["dds.max_participant_index"] = args.max_participant_index
    if args.ros1_robots or args.ros_masters:
        overrides["ros1.robots"] = _ros1_robot_overrides(args.ros1_robots or [], args.ros_masters or [])
    if args.external_url is not None:
        overrides["web.external_url"] = args.external_url
    if args.enable_maintenance_api:
        overrides["web.enable_maintenance_api"] = True
    for name in ("stale_after", "robot_timeout", "expire_after"):
        value = getattr(args, name)
        if value is not None:
            overrides[f"fleet.{name}"] = parse_duration(value, f"--fleet.{name.replace('_', '-')}")
    if args.robot_namespace_depth is not None:
        overrides["fleet.robot_namespace_depth"] = args.robot_namespace_depth
    if args.dds_disabled:
        overrides["dds.enabled"] = False
    overrides.update(_zenoh_overrides(args))
    overrides.update(_ros2_overrides(args))
    if args.shard is not None:
        overrides["shard"] = args.shard
    if args.ingest_workers is not None:
        overrides["ingest.workers"] = args.ingest_workers
    if args.log_level is not None:
        overrides["log_level"] = args.log_level
    overrides.update(_event_overrides(args))
    overrides.update(_given_flags(args, "icinga2", (flag.replace("-", "_") for flag, _, _ in _ICINGA2_FLAGS)))
    return overrides


def _event_overrides(args: argparse.Namespace) -> dict[str, Any]:
    overrides: dict[str, Any] = {}
    if args.log_format is not None:
        overrides["log_format"] = args.log_format
    if args.events_path is not None:
        overrides["events.path"] = args.events_path
    if args.events_retention is not None:
        overrides["events.retention"] = parse_duration(args.events_retention, "--events.retention")
    if args.events_max_size is not None:
        overrides["events.max_size"] = parse_max_size(args.events_max_size, "--events.max-size")
    return overrides


def _ros1_robot_overrides(named: list[str], masters: list[str]) -> list[dict[str, str]]:
    """ros1.robots from `--ros1.robot NAME=URI` and `--ros-master URI`; a bare NAME names the one master."""
    robots = []
    names_for_master = []
    for text in named:
        name, sep, uri = text.partition("=")
        if sep:
            robots.append({"name": name, "master_uri": uri})
        elif len(masters) == 1 and name:
            names_for_master.append(name)
        else:
            raise ConfigError(
                "--ros1.robot: expected NAME=MASTER_URI (or NAME with exactly one --ros-master), "
                f"got {text!r}"
            )
    if len(names_for_master) > 1:
        raise ConfigError(f"--ros1.robot: one name for the one --ros-master, got {names_for_master}")
    for uri in masters:
        robots.append({"master_uri": uri, **({"name": names_for_master[0]} if names_for_master else {})})
    return robots


def _zenoh_overrides(args: argparse.Namespace) -> dict[str, Any]:
    """The `zenoh.*` keys given as flags; any of them turns the Zenoh transport on."""
    return _given_flags(args, "zenoh", ("connect", "listen", "mode", "domain", "config"))


def _wait_for_signal() -> None:
    """Return at SIGTERM or SIGINT; from then on a second one ends the process at once."""
    stop = threading.Event()

    def first(signum: int, _frame: object) -> None:
        stop.set()
        for sig in (signal.SIGTERM, signal.SIGINT):
            signal.signal(sig, again)

    def again(signum: int, _frame: object) -> None:
        log.warning("%s again while stopping: leaving at once", signal.Signals(signum).name)
        logging.shutdown()
        os._exit(128 + signum)

    for sig in (signal.SIGTERM, signal.SIGINT):
        signal.signal(sig, first)
    while not stop.wait(1.0):
        pass
    log.info("stopping")


def _run(args: argparse.Namespace) -> int:
    config = load_config(args.config_file, _exporter_overrides(args))
    configure_logging(config.log_level, config.log_format)
    from overseer.app import Exporter
    from overseer.fleet.workers.pool import WorkerStartError

    try:
        exporter = Exporter(config)
    except OSError as error:
        print(
            f"overseer run: cannot listen on {config.web.listen_address}: {error.strerror}", file=sys.stderr
        )
        return 1
    try:
        exporter.start()
    except WorkerStartError as error:
        print(f"overseer run: {error}", file=sys.stderr)
        return 1
    _wait_for_signal()
    if not exporter.stop():
        return 1
    log.info("stopped")
    return 0


def _simulator_settings(args: argparse.Namespace) -> Any:
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


def _simulate(args: argparse.Namespace) -> int:
    settings = _simulator_settings(args)
    configure_logging(args.log_level)
    from overseer.simulator.publisher import EventError, FleetSimulator

    try:
        if args.transport == "dds":
            simulator = FleetSimulator(settings)
        elif args.transport == "zenoh":
            simulator = _zenoh_simulator(args, settings)
        else:
            from overseer.sources.ros2 import require_rclpy

            require_rclpy("--transport ros2")
            from overseer.simulator.ros2_publisher import Ros2FleetSimulator

            simulator = Ros2FleetSimulator(settings, best_effort=args.ros2_qos == "best_effort")
    except (EventError, ValueError) as error:
        raise ConfigError(str(error)) from None
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


def _zenoh_simulator(args: argparse.Namespace, settings: Any) -> Any:
    """The simulator publishing over Zenoh, as rmw_zenoh or as zenoh-bridge-ros2dds does."""
    from overseer.simulator.zenoh_publisher import ZenohFleetSimulator, ZenohSettings
    from overseer.sources.zenoh.keys import DIAGNOSTIC_ARRAY_HASH

    type_hash = args.zenoh_type_hash or DIAGNOSTIC_ARRAY_HASH
    if not re.fullmatch(r"[A-Za-z0-9_]+", type_hash):
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


def _demo(args: argparse.Namespace) -> int:
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
    _wait_for_signal()
    simulator.stop()
    thread.join(timeout=5)
    exporter.stop()
    log.info("demo ran for %.0fs", time.monotonic() - started)
    return 0


if __name__ == "__main__":
    sys.exit(main())
