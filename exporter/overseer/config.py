"""The exporter's configuration: one dataclass tree, read from YAML and flags, validated at start.

Every error names the offending key and value, so the CLI can fail with one readable line.
"""

from __future__ import annotations

import os
import re
from dataclasses import dataclass, field, fields, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

import yaml

from overseer.model import FleetLimits
from overseer.model.shard import Shard
from overseer.ros_master import master_host
from overseer.serve.message_labels import DEFAULT_MESSAGE_LABEL_LENGTH, MESSAGE_LABEL_MODES

if TYPE_CHECKING:
    from overseer.push.icinga2_config import Icinga2Config

DEFAULT_PORT = 9849
DIAGNOSTIC_TOPICS = ("diagnostics_agg", "diagnostics")
# rmw_cyclonedds (Iron and later) lets a robot's DDS processes take participant indices 0..32.
DEFAULT_MAX_PARTICIPANT_INDEX = 32
MAX_PARTICIPANT_INDEX_LIMIT = 119


class ConfigError(ValueError):
    """A configuration that cannot be used; the message names the key and the bad value."""


@dataclass(frozen=True)
class DomainConfig:
    """A DDS domain to join; `robot_name` names a robot whose diagnostics topic has no namespace."""

    id: int
    robot_name: str | None = None

    @property
    def unnamespaced_robot(self) -> str:
        """The robot name for `rt/diagnostics_agg` on this domain."""
        return self.robot_name or f"domain{self.id}"


@dataclass(frozen=True)
class DdsPeer:
    """A host DDS discovery is sent to directly; with no `port`, every participant index's port on it."""

    host: str
    port: int | None = None

    def __str__(self) -> str:
        return self.host if self.port is None else f"{self.host}:{self.port}"

    @property
    def is_loopback(self) -> bool:
        """True for `localhost` and 127.0.0.0/8."""
        return self.host == "localhost" or (
            _IPV4.fullmatch(self.host) is not None and self.host.startswith("127.")
        )


@dataclass(frozen=True)
class DdsConfig:
    """The ROS 2 / DDS transport."""

    enabled: bool = True
    domains: tuple[DomainConfig, ...] = (DomainConfig(0),)
    topics: tuple[str, ...] = DIAGNOSTIC_TOPICS
    prefer_aggregated: bool = True
    loopback_only: bool = False
    cyclonedds_uri: str | None = None
    peers: tuple[DdsPeer, ...] = ()
    max_participant_index: int = DEFAULT_MAX_PARTICIPANT_INDEX


@dataclass(frozen=True)
class Ros1Robot:
    """A ROS 1 robot: its name and its master's XML-RPC URI."""

    name: str
    master_uri: str
    topic: str = "diagnostics_agg"


@dataclass(frozen=True)
class Ros1Config:
    """The ROS 1 transport: XML-RPC to each robot's master, TCPROS to its publishers."""

    robots: tuple[Ros1Robot, ...] = ()
    caller_id: str = "/overseer"
    advertise_host: str | None = None
    reconnect_min: float = 0.5
    reconnect_max: float = 30.0
    poll_interval: float = 5.0

    @property
    def enabled(self) -> bool:
        """True when any ROS 1 robot is configured."""
        return bool(self.robots)


ZENOH_MODES = ("client", "peer")
ZENOH_KEY_FORMATS = ("rmw_zenoh", "bridge")


@dataclass(frozen=True)
class ZenohConfig:
    """The Zenoh transport: rmw_zenoh robots and robots behind zenoh-bridge-ros2dds, through routers."""

    enabled: bool = False
    mode: str | None = None  # client of one router, peer of several, unless the Zenoh config file says
    connect: tuple[str, ...] = ()
    listen: tuple[str, ...] = ()
    domain: int = 0
    config: str | None = None  # a native Zenoh JSON5 configuration file (TLS, access control)
    key_formats: tuple[str, ...] = ZENOH_KEY_FORMATS
    robot_name: str | None = None  # for diagnostics topics without a namespace (default "domain<N>")
    multicast_scouting: bool = False

    @property
    def unnamespaced_robot(self) -> str:
        """The robot name for `/diagnostics_agg` without a namespace."""
        return self.robot_name or f"domain{self.domain}"


@dataclass(frozen=True)
class WebConfig:
    """The HTTP endpoint; `config_file` is an exporter-toolkit web config (TLS, basic auth)."""

    listen_address: str = f":{DEFAULT_PORT}"
    config_file: str | None = None
    external_url: str | None = None  # the URL users reach us at, for links in alerts (no trailing /)

    @property
    def host_and_port(self) -> tuple[str, int]:
        """The address split into a bind host ('' for all interfaces) and a port."""
        return parse_listen_address(self.listen_address)


@dataclass(frozen=True)
class MetricsConfig:
    """What the /metrics view exports beyond levels."""

    value_keys: tuple[str, ...] = (".*",)
    # Which components get ros_diagnostics_status_message (none, problems, all), and how many characters
    # its message label keeps, "…" included when cut.
    message_labels: str = "problems"
    message_label_length: int = DEFAULT_MESSAGE_LABEL_LENGTH

    @property
    def value_key_pattern(self) -> re.Pattern[str]:
        """One compiled pattern matching every allowed key-value key in full."""
        return re.compile("|".join(f"(?:{p})" for p in self.value_keys) or "(?!)")


@dataclass(frozen=True)
class EventsConfig:
    """The event history: an SQLite file of the fleet's transitions, and how much of it to keep."""

    enabled: bool = True
    path: str = "overseer-events.db"  # relative to the working directory
    retention: float = 30 * 86400.0  # seconds
    max_size: int = 1_000_000_000  # bytes


MAX_INGEST_WORKERS = 64
DEFAULT_INGEST_WORKERS_CAP = 16


def default_ingest_workers() -> int:
    """One ingest worker per core this process may run on, at most `DEFAULT_INGEST_WORKERS_CAP`."""
    try:
        cores = len(os.sched_getaffinity(0))  # honours taskset and cpusets, unlike cpu_count
    except AttributeError:  # not on Linux
        cores = os.cpu_count() or 1
    return max(1, min(cores, DEFAULT_INGEST_WORKERS_CAP))


@dataclass(frozen=True)
class IngestConfig:
    """How many worker processes share the ingest; 1 runs it in the exporter's own process."""

    workers: int = field(default_factory=default_ingest_workers)


@dataclass(frozen=True)
class Config:
    """The whole configuration."""

    web: WebConfig = field(default_factory=WebConfig)
    dds: DdsConfig = field(default_factory=DdsConfig)
    ros1: Ros1Config = field(default_factory=Ros1Config)
    zenoh: ZenohConfig = field(default_factory=ZenohConfig)
    fleet: FleetLimits = field(default_factory=FleetLimits)
    metrics: MetricsConfig = field(default_factory=MetricsConfig)
    shard: Shard = field(default_factory=Shard)
    ingest: IngestConfig = field(default_factory=IngestConfig)
    log_level: str = "info"
    events: EventsConfig = field(default_factory=EventsConfig)
    log_format: str = "text"
    icinga2: Icinga2Config | None = None  # push to Icinga 2 when set


_DURATION_PART = re.compile(r"(\d+(?:\.\d+)?)(ms|s|m|h|d)")
_DURATION_UNITS = {"ms": 0.001, "s": 1.0, "m": 60.0, "h": 3600.0, "d": 86400.0}
_LOG_LEVELS = ("debug", "info", "warning", "error")
_LOG_FORMATS = ("text", "json")
_SIZE = re.compile(r"(\d+(?:\.\d+)?)\s*(B|kB|KB|MB|GB|TB|KiB|MiB|GiB|TiB)?")
_SIZE_UNITS = {
    None: 1,
    "B": 1,
    "kB": 1000,
    "KB": 1000,
    "MB": 1000**2,
    "GB": 1000**3,
    "TB": 1000**4,
    "KiB": 1024,
    "MiB": 1024**2,
    "GiB": 1024**3,
    "TiB": 1024**4,
}
MIN_EVENTS_SIZE = 1_000_000


def parse_duration(value: object, key: str) -> float:
    """Seconds from a number or a Prometheus-style duration such as `5s`, `1h30m`, `250ms`."""
    if isinstance(value, bool):
        raise ConfigError(f"{key}: expected a duration such as 5s, got {value!r}")
    if isinstance(value, int | float):
        seconds = float(value) if abs(value) < 1e300 else float("inf")  # float(10**400) would raise
    elif isinstance(value, str) and value and _DURATION_PART.sub("", value) == "":
        seconds = sum(float(n) * _DURATION_UNITS[u] for n, u in _DURATION_PART.findall(value))
    else:
        raise ConfigError(f"{key}: expected a duration such as 5s, got {value!r}")
    if not seconds > 0 or seconds == float("inf"):
        raise ConfigError(f"{key}: must be a positive duration, got {value!r}")
    return seconds


def parse_size(value: object, key: str) -> int:
    """Bytes from a number or a size such as `500MB`, `1GB`, `2GiB`."""
    match = _SIZE.fullmatch(value.strip()) if isinstance(value, str) else None
    if isinstance(value, int) and not isinstance(value, bool):
        size = value
    elif match is not None:
        size = int(float(match.group(1)) * _SIZE_UNITS[match.group(2)])
    else:
        raise ConfigError(f"{key}: expected a size such as 500MB or 1GB, got {value!r}")
    if size < MIN_EVENTS_SIZE:
        raise ConfigError(f"{key}: must be at least 1MB, got {value!r}")
    return size


def parse_listen_address(value: str) -> tuple[str, int]:
    """Split `host:port` (host may be empty or a bracketed IPv6 address) into host and port."""
    host, sep, port = value.rpartition(":")
    if not sep or not port.isdigit() or not 0 <= int(port) <= 65535:
        raise ConfigError(f"web.listen_address: expected host:port, got {value!r}")
    return host.strip("[]"), int(port)


def parse_shard(value: object, key: str = "shard") -> Shard:
    """A `Shard` from `i/n` with 0 <= i < n."""
    match = re.fullmatch(r"(\d+)/(\d+)", value) if isinstance(value, str) else None
    if match is None or not 0 <= int(match.group(1)) < int(match.group(2)):
        raise ConfigError(f"{key}: expected i/n with 0 <= i < n, such as 0/2, got {value!r}")
    return Shard(int(match.group(1)), int(match.group(2)))


_HOST_LABEL = re.compile(r"(?!-)[A-Za-z0-9-]{1,63}(?<!-)")
_IPV4 = re.compile(r"(\d{1,3})\.(\d{1,3})\.(\d{1,3})\.(\d{1,3})")


def parse_dds_peer(value: object, key: str) -> DdsPeer:
    """A `DdsPeer` from `HOST` or `HOST:PORT`; HOST is an IPv4 address or a DNS name."""
    if not isinstance(value, str):
        raise ConfigError(f"{key}: expected HOST or HOST:PORT, got {value!r}")
    host, sep, port_text = value.partition(":")
    port: int | None = None
    if sep:
        if not port_text.isdigit() or not 1 <= int(port_text) <= 65535:
            raise ConfigError(f"{key}: expected a port from 1 to 65535 after the host, got {value!r}")
        port = int(port_text)
    ipv4 = _IPV4.fullmatch(host)
    if ipv4 is not None:
        if any(int(part) > 255 for part in ipv4.groups()):
            raise ConfigError(f"{key}: {host!r} is not an IPv4 address, in {value!r}")
    elif len(host) > 253 or not all(_HOST_LABEL.fullmatch(label) for label in host.split(".")):
        raise ConfigError(
            f"{key}: expected HOST or HOST:PORT with an IPv4 address or a host name, got {value!r}"
        )
    return DdsPeer(host, port)


def load_config(path: str | Path | None, overrides: dict[str, Any] | None = None) -> Config:
    """Read the YAML file at `path` (None for defaults) and apply dotted-key `overrides` from flags."""
    raw: dict[str, Any] = {}
    if path is not None:
        try:
            text = Path(path).read_text(encoding="utf-8")
        except OSError as error:
            raise ConfigError(f"config.file: cannot read {str(path)!r}: {error.strerror}") from None
        try:
            loaded = yaml.safe_load(text)
        except (yaml.YAMLError, ValueError, RecursionError) as error:  # also huge integers, deep nesting
            raise ConfigError(f"config.file: {str(path)!r} is not valid YAML: {_first_line(error)}") from None
        if loaded is not None and not isinstance(loaded, dict):
            raise ConfigError(f"config.file: expected a mapping at the top of {str(path)!r}")
        raw = loaded or {}
    for dotted, value in (overrides or {}).items():
        section, _, key = dotted.partition(".")
        target = raw.setdefault(section, {}) if key else raw
        if not isinstance(target, dict):
            raise ConfigError(f"{section}: expected a mapping, got {target!r}")
        target[key or section] = value
    return config_from_dict(raw)


def config_from_dict(raw: dict[str, Any]) -> Config:
    """Validate a parsed configuration mapping into a `Config`."""
    _reject_unknown(
        raw,
        "",
        {
            "web",
            "dds",
            "ros1",
            "zenoh",
            "fleet",
            "metrics",
            "shard",
            "ingest",
            "log_level",
            "events",
            "log_format",
            "icinga2",
        },
    )
    web = _section(raw, "web", {"listen_address", "config_file", "external_url"})
    dds = _section(raw, "dds", {f.name for f in fields(DdsConfig)})
    ros1 = _section(raw, "ros1", {f.name for f in fields(Ros1Config)})
    zenoh = _section(raw, "zenoh", {f.name for f in fields(ZenohConfig)})
    fleet = _section(raw, "fleet", {f.name for f in fields(FleetLimits)})
    metrics = _section(raw, "metrics", {"value_keys", "message_labels", "message_label_length"})

    config = Config()
    if "listen_address" in web:
        address = _string(web["listen_address"], "web.listen_address")
        parse_listen_address(address)
        config = replace(config, web=WebConfig(address))
    if web.get("config_file") is not None:
        config = replace(
            config, web=replace(config.web, config_file=_string(web["config_file"], "web.config_file"))
        )
    if web.get("external_url") is not None:
        config = replace(config, web=replace(config.web, external_url=_external_url(web["external_url"])))
    config = replace(
        config,
        dds=_dds_config(dds),
        ros1=_ros1_config(ros1),
        zenoh=_zenoh_config(zenoh),
        fleet=_fleet_limits(fleet),
        metrics=_metrics_config(metrics),
    )
    if "shard" in raw:
        config = replace(config, shard=parse_shard(raw["shard"]))
    ingest = _section(raw, "ingest", {"workers"})
    if ingest.get("workers") is not None:
        config = replace(config, ingest=IngestConfig(_ingest_workers(ingest["workers"])))
    if "log_level" in raw:
        level = _string(raw["log_level"], "log_level").lower()
        if level not in _LOG_LEVELS:
            raise ConfigError(
                f"log_level: expected one of {', '.join(_LOG_LEVELS)}, got {raw['log_level']!r}"
            )
        config = replace(config, log_level=level)
    if "log_format" in raw:
        log_format = _string(raw["log_format"], "log_format").lower()
        if log_format not in _LOG_FORMATS:
            raise ConfigError(f"log_format: expected text or json, got {raw['log_format']!r}")
        config = replace(config, log_format=log_format)
    events = _section(raw, "events", {f.name for f in fields(EventsConfig)})
    config = replace(config, events=_events_config(events))
    if raw.get("icinga2") is not None:
        from overseer.push.icinga2_config import icinga2_config  # imports this module: not at the top

        config = replace(config, icinga2=icinga2_config(raw["icinga2"]))
    return config


def _ingest_workers(value: object) -> int:
    if isinstance(value, str) and value.strip().isdigit():
        value = int(value)
    if isinstance(value, bool) or not isinstance(value, int) or not 1 <= value <= MAX_INGEST_WORKERS:
        raise ConfigError(
            f"ingest.workers: expected a whole number from 1 to {MAX_INGEST_WORKERS}, got {value!r}"
        )
    return value


def _events_config(raw: dict[str, Any]) -> EventsConfig:
    defaults = EventsConfig()
    return EventsConfig(
        enabled=_bool(raw.get("enabled", defaults.enabled), "events.enabled"),
        path=_string(raw["path"], "events.path") if "path" in raw else defaults.path,
        retention=parse_duration(raw["retention"], "events.retention")
        if "retention" in raw
        else defaults.retention,
        max_size=parse_size(raw["max_size"], "events.max_size") if "max_size" in raw else defaults.max_size,
    )


def _dds_config(raw: dict[str, Any]) -> DdsConfig:
    defaults = DdsConfig()
    domains = defaults.domains
    if "domains" in raw:
        items = raw["domains"]
        if not isinstance(items, list) or not items:
            raise ConfigError(f"dds.domains: expected a non-empty list, got {items!r}")
        domains = tuple(_domain(item, f"dds.domains[{i}]") for i, item in enumerate(items))
        ids = [d.id for d in domains]
        if len(set(ids)) != len(ids):
            raise ConfigError(f"dds.domains: domain ids must be unique, got {ids}")
    topics = defaults.topics
    if "topics" in raw:
        topics = tuple(_string(t, "dds.topics") for t in _list(raw["topics"], "dds.topics"))
        for topic in topics:
            if topic not in DIAGNOSTIC_TOPICS:
                raise ConfigError(f"dds.topics: expected diagnostics_agg or diagnostics, got {topic!r}")
    uri = raw.get("cyclonedds_uri")
    loopback_only = _bool(raw.get("loopback_only", defaults.loopback_only), "dds.loopback_only")
    peers = _dds_peers([] if raw.get("peers") is None else raw["peers"], loopback_only)
    max_index = _max_participant_index(raw.get("max_participant_index", defaults.max_participant_index))
    for domain in domains if peers else ():
        highest_port = 7400 + 250 * domain.id + 11 + 2 * max_index  # unicast data port of the last index
        if highest_port > 65535:
            raise ConfigError(
                f"dds.max_participant_index: {max_index} needs port {highest_port} on domain {domain.id}, "
                "above 65535"
            )
    return DdsConfig(
        enabled=_bool(raw.get("enabled", defaults.enabled), "dds.enabled"),
        domains=domains,
        topics=topics,
        prefer_aggregated=_bool(
            raw.get("prefer_aggregated", defaults.prefer_aggregated), "dds.prefer_aggregated"
        ),
        loopback_only=loopback_only,
        cyclonedds_uri=None if uri is None else _string(uri, "dds.cyclonedds_uri"),
        peers=peers,
        max_participant_index=max_index,
    )


def _dds_peers(items: object, loopback_only: bool) -> tuple[DdsPeer, ...]:
    peers = tuple(parse_dds_peer(item, f"dds.peers[{i}]") for i, item in enumerate(_list(items, "dds.peers")))
    for i, peer in enumerate(peers):
        if loopback_only and not peer.is_loopback:
            raise ConfigError(
                f"dds.peers[{i}]: {str(peer)!r} is not a loopback address, but dds.loopback_only keeps DDS "
                "on loopback"
            )
    return peers


def _max_participant_index(value: object) -> int:
    # Cyclone 11 never hands out the highest index of its range itself, so 0 would leave the exporter none.
    if not isinstance(value, int) or isinstance(value, bool) or not 1 <= value <= MAX_PARTICIPANT_INDEX_LIMIT:
        raise ConfigError(
            f"dds.max_participant_index: expected an integer from 1 to {MAX_PARTICIPANT_INDEX_LIMIT}, "
            f"got {value!r}"
        )
    return value


def _ros1_config(raw: dict[str, Any]) -> Ros1Config:
    defaults = Ros1Config()
    robots = tuple(
        _ros1_robot(item, f"ros1.robots[{i}]")
        for i, item in enumerate(_list(raw.get("robots", []), "ros1.robots"))
    )
    names = [robot.name for robot in robots]
    if len(set(names)) != len(names):
        raise ConfigError(f"ros1.robots: robot names must be unique, got {names}")
    masters = [robot.master_uri.rstrip("/") for robot in robots]
    if len(set(masters)) != len(masters):
        # Two subscriptions with one caller id on one master keep shutting each other down.
        raise ConfigError(f"ros1.robots: each robot needs a master of its own, got {masters}")
    values: dict[str, Any] = {}
    for key in ("reconnect_min", "reconnect_max", "poll_interval"):
        if key in raw:
            values[key] = parse_duration(raw[key], f"ros1.{key}")
    for key in ("caller_id", "advertise_host"):
        if key in raw:
            values[key] = _string(raw[key], f"ros1.{key}")
    config = replace(defaults, robots=robots, **values)
    if config.reconnect_max < config.reconnect_min:
        raise ConfigError(
            f"ros1.reconnect_max: must not be shorter than ros1.reconnect_min, got {config.reconnect_max:g}s"
        )
    return config


_ZENOH_ENDPOINT = re.compile(r"[a-z][a-z0-9-]*/\S+")


def _zenoh_config(raw: dict[str, Any]) -> ZenohConfig:
    """Any Zenoh key turns the transport on, unless `enabled` says otherwise."""
    defaults = ZenohConfig()
    mode = raw.get("mode", defaults.mode)
    if mode is not None and mode not in ZENOH_MODES:
        raise ConfigError(f"zenoh.mode: expected client or peer, got {mode!r}")
    endpoints: dict[str, tuple[str, ...]] = {}
    for key in ("connect", "listen"):
        values = raw.get(key, [])
        items = tuple(_string(v, f"zenoh.{key}") for v in (values if isinstance(values, list) else [values]))
        for endpoint in items:
            if not _ZENOH_ENDPOINT.fullmatch(endpoint):
                raise ConfigError(
                    f"zenoh.{key}: expected an endpoint such as tcp/host:7447, got {endpoint!r}"
                )
        endpoints[key] = items
    domain = raw.get("domain", defaults.domain)
    if not isinstance(domain, int) or isinstance(domain, bool) or not 0 <= domain <= 232:
        raise ConfigError(f"zenoh.domain: expected a ROS domain id from 0 to 232, got {domain!r}")
    formats = defaults.key_formats
    if "key_formats" in raw:
        listed = _list(raw["key_formats"], "zenoh.key_formats")
        formats = tuple(_string(f, "zenoh.key_formats") for f in listed)
        for name in formats:
            if name not in ZENOH_KEY_FORMATS:
                raise ConfigError(f"zenoh.key_formats: expected rmw_zenoh or bridge, got {name!r}")
        if not formats:
            raise ConfigError("zenoh.key_formats: expected at least one of rmw_zenoh, bridge, got []")
    file = raw.get("config")
    if file is not None and not Path(_string(file, "zenoh.config")).is_file():
        raise ConfigError(f"zenoh.config: cannot read {file!r}: no such file")
    robot_name = raw.get("robot_name")
    return ZenohConfig(
        enabled=_bool(raw.get("enabled", bool(raw)), "zenoh.enabled"),
        mode=mode,
        connect=endpoints["connect"],
        listen=endpoints["listen"],
        domain=domain,
        config=file,
        key_formats=formats,
        robot_name=None if robot_name is None else _string(robot_name, "zenoh.robot_name"),
        multicast_scouting=_bool(
            raw.get("multicast_scouting", defaults.multicast_scouting), "zenoh.multicast_scouting"
        ),
    )


def _ros1_robot(item: object, key: str) -> Ros1Robot:
    if not isinstance(item, dict):
        raise ConfigError(f"{key}: expected a mapping with name and master_uri, got {item!r}")
    _reject_unknown(item, key + ".", {"name", "master_uri", "topic"})
    master_uri = _string(item.get("master_uri"), f"{key}.master_uri")
    if not re.fullmatch(r"https?://[^/\s:]+(:\d+)?/?", master_uri):
        raise ConfigError(f"{key}.master_uri: expected http://HOST:PORT, got {master_uri!r}")
    name = _string(item["name"], f"{key}.name") if "name" in item else master_host(master_uri)
    topic = _string(item.get("topic", "diagnostics_agg"), f"{key}.topic")
    if topic not in DIAGNOSTIC_TOPICS:
        raise ConfigError(f"{key}.topic: expected diagnostics_agg or diagnostics, got {topic!r}")
    return Ros1Robot(name, master_uri, topic)


def _domain(item: object, key: str) -> DomainConfig:
    if isinstance(item, int) and not isinstance(item, bool):
        item = {"id": item}
    if not isinstance(item, dict):
        raise ConfigError(f"{key}: expected a domain id or a mapping with id, got {item!r}")
    _reject_unknown(item, key + ".", {"id", "robot_name"})
    domain_id = item.get("id")
    if not isinstance(domain_id, int) or isinstance(domain_id, bool) or not 0 <= domain_id <= 232:
        raise ConfigError(f"{key}.id: expected a DDS domain id from 0 to 232, got {domain_id!r}")
    name = item.get("robot_name")
    return DomainConfig(domain_id, None if name is None else _string(name, f"{key}.robot_name"))


def _fleet_limits(raw: dict[str, Any]) -> FleetLimits:
    values: dict[str, Any] = {}
    for f in fields(FleetLimits):
        if f.name not in raw:
            continue
        key = f"fleet.{f.name}"
        if f.name.startswith("max_"):
            value = raw[f.name]
            if not isinstance(value, int) or isinstance(value, bool) or value < 1:
                raise ConfigError(f"{key}: expected a positive integer, got {value!r}")
            values[f.name] = value
        else:
            values[f.name] = parse_duration(raw[f.name], key)
    limits = FleetLimits(**values)
    if limits.robot_timeout < limits.stale_after:
        raise ConfigError(
            f"fleet.robot_timeout: must not be shorter than fleet.stale_after ({limits.stale_after:g}s), "
            f"got {limits.robot_timeout:g}s"
        )
    if limits.expire_after < limits.robot_timeout:
        raise ConfigError(
            f"fleet.expire_after: must not be shorter than fleet.robot_timeout ({limits.robot_timeout:g}s), "
            f"got {limits.expire_after:g}s"
        )
    return limits


def _external_url(value: object) -> str:
    url = _string(value, "web.external_url")
    if not re.fullmatch(r"https?://[^/\s?#]+(/[^\s?#]*)?", url):
        raise ConfigError(f"web.external_url: expected http(s)://HOST[:PORT][/PATH], got {url!r}")
    return url.rstrip("/")


def _metrics_config(raw: dict[str, Any]) -> MetricsConfig:
    config = _message_labels(raw)
    if "value_keys" not in raw:
        return config
    patterns = tuple(_string(p, "metrics.value_keys") for p in _list(raw["value_keys"], "metrics.value_keys"))
    for pattern in patterns:
        try:
            re.compile(pattern)
        except re.error as error:
            raise ConfigError(
                f"metrics.value_keys: {pattern!r} is not a regular expression: {error}"
            ) from None
    return replace(config, value_keys=patterns)


def _message_labels(raw: dict[str, Any]) -> MetricsConfig:
    config = MetricsConfig()
    if "message_labels" in raw:
        mode = raw["message_labels"]
        if mode not in MESSAGE_LABEL_MODES:
            raise ConfigError(
                f"metrics.message_labels: expected one of {', '.join(MESSAGE_LABEL_MODES)}, got {mode!r}"
            )
        config = replace(config, message_labels=mode)
    if "message_label_length" in raw:
        length = raw["message_label_length"]
        if not isinstance(length, int) or isinstance(length, bool) or not 1 <= length <= 1024:
            raise ConfigError(
                f"metrics.message_label_length: expected an integer from 1 to 1024, got {length!r}"
            )
        config = replace(config, message_label_length=length)
    return config


def _section(raw: dict[str, Any], name: str, allowed: set[str]) -> dict[str, Any]:
    section = raw.get(name) or {}
    if not isinstance(section, dict):
        raise ConfigError(f"{name}: expected a mapping, got {section!r}")
    _reject_unknown(section, name + ".", allowed)
    return section


def _reject_unknown(raw: dict[str, Any], prefix: str, allowed: set[str]) -> None:
    for key in raw:
        if key not in allowed:
            shown = key if isinstance(key, str) and key.isprintable() and key else repr(key)
            raise ConfigError(f"{prefix}{shown}: unknown key (expected one of {', '.join(sorted(allowed))})")


def _string(value: object, key: str) -> str:
    if not isinstance(value, str) or not value:
        raise ConfigError(f"{key}: expected a non-empty string, got {value!r}")
    return value


def _bool(value: object, key: str) -> bool:
    if not isinstance(value, bool):
        raise ConfigError(f"{key}: expected true or false, got {value!r}")
    return value


def _list(value: object, key: str) -> list[Any]:
    if not isinstance(value, list):
        raise ConfigError(f"{key}: expected a list, got {value!r}")
    return value


def read_text_file(path: str | Path, key: str) -> str:
    """The UTF-8 text of the file `key` names; ConfigError naming the key when it cannot be read."""
    try:
        return Path(path).read_text(encoding="utf-8")
    except OSError as error:
        raise ConfigError(f"{key}: cannot read {str(path)!r}: {error.strerror}") from None
    except UnicodeDecodeError:
        raise ConfigError(f"{key}: {str(path)!r} is not UTF-8 text") from None


def _first_line(error: Exception) -> str:
    return " ".join(str(error).split())
