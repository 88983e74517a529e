"""The `dds:` section: the DDS domains to join, the topics to follow, and how discovery reaches robots."""

from __future__ import annotations

import re
from dataclasses import dataclass
from typing import Any

from overseer.config.errors import ConfigError
from overseer.config.options import Option, option
from overseer.config.parsers import boolean, listed, reject_unknown, string, whole_number
from overseer.config.topics import DIAGNOSTIC_TOPICS

# rmw_cyclonedds (Iron and later) lets a robot's DDS processes take participant indices 0..32.
DEFAULT_MAX_PARTICIPANT_INDEX = 32
MAX_PARTICIPANT_INDEX_LIMIT = 119
_HOST_LABEL = re.compile(r"(?!-)[A-Za-z0-9-]{1,63}(?<!-)")
_IPV4 = re.compile(r"(\d{1,3})\.(\d{1,3})\.(\d{1,3})\.(\d{1,3})")


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


OPTIONS: tuple[Option, ...] = (
    option(
        "dds.enabled",
        "on",
        "join DDS; the flag turns it off, for a fleet reached over Zenoh or ROS 1 only",
        kind="switch",
        flag="--dds.disabled",
        value=False,
    ),
    option(
        "dds.domains",
        "ROS_DOMAIN_ID, else 0",
        "a DDS domain (= ROS_DOMAIN_ID) to join; repeat for several. In the file, a domain may be "
        "{id: 57, robot_name: robot57}: one robot, named, for its un-namespaced topics (without a name "
        "they are robot domain<ID>, or named by their nodes' namespaces)",
        kind="repeated",
        metavar="ID",
        flag="--dds.domain",
    ),
    option(
        "dds.topics",
        "diagnostics_agg, diagnostics",
        "a diagnostics topic to follow, diagnostics_agg or diagnostics; repeat for both",
        kind="repeated",
        metavar="TOPIC",
        flag="--dds.topic",
    ),
    option(
        "dds.prefer_aggregated",
        "true",
        "read a robot that publishes both topics from diagnostics_agg only (true or false)",
        metavar="BOOL",
    ),
    option(
        "dds.loopback_only", "off", "keep DDS traffic on the loopback interface (tests, demos)", kind="switch"
    ),
    option(
        "dds.cyclonedds_uri",
        "Cyclone's own (CYCLONEDDS_URI)",
        "Cyclone DDS configuration, XML text or file://…",
        metavar="URI",
    ),
    option(
        "dds.peers",
        "none",
        "send DDS discovery straight to this host, for robots on networks without multicast "
        "(docs/networks.md); repeat for several",
        kind="repeated",
        metavar="HOST[:PORT]",
        flag="--dds.peer",
    ),
    option(
        "dds.max_participant_index",
        str(DEFAULT_MAX_PARTICIPANT_INDEX),
        "probe participant indices 0…N (one per DDS process) on each peer without a port",
        metavar="N",
    ),
)
KEYS = {entry.key.partition(".")[2] for entry in OPTIONS}


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


def dds_config(raw: dict[str, Any]) -> DdsConfig:
    """The section from its mapping."""
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
        topics = tuple(string(t, "dds.topics") for t in listed(raw["topics"], "dds.topics"))
        for topic in topics:
            if topic not in DIAGNOSTIC_TOPICS:
                raise ConfigError(f"dds.topics: expected diagnostics_agg or diagnostics, got {topic!r}")
    uri = raw.get("cyclonedds_uri")
    loopback_only = boolean(raw.get("loopback_only", defaults.loopback_only), "dds.loopback_only")
    peers = _dds_peers([] if raw.get("peers") is None else raw["peers"], loopback_only)
    # Cyclone 11 never hands out the highest index of its range itself, so 0 would leave the exporter none.
    max_index = whole_number(
        raw.get("max_participant_index", defaults.max_participant_index),
        "dds.max_participant_index",
        1,
        MAX_PARTICIPANT_INDEX_LIMIT,
    )
    for domain in domains if peers else ():
        highest_port = 7400 + 250 * domain.id + 11 + 2 * max_index  # unicast data port of the last index
        if highest_port > 65535:
            raise ConfigError(
                f"dds.max_participant_index: {max_index} needs port {highest_port} on domain {domain.id}, "
                "above 65535"
            )
    return DdsConfig(
        enabled=boolean(raw.get("enabled", defaults.enabled), "dds.enabled"),
        domains=domains,
        topics=topics,
        prefer_aggregated=boolean(
            raw.get("prefer_aggregated", defaults.prefer_aggregated), "dds.prefer_aggregated"
        ),
        loopback_only=loopback_only,
        cyclonedds_uri=None if uri is None else string(uri, "dds.cyclonedds_uri"),
        peers=peers,
        max_participant_index=max_index,
    )


def _dds_peers(items: object, loopback_only: bool) -> tuple[DdsPeer, ...]:
    peers = tuple(
        parse_dds_peer(item, f"dds.peers[{i}]") for i, item in enumerate(listed(items, "dds.peers"))
    )
    for i, peer in enumerate(peers):
        if loopback_only and not peer.is_loopback:
            raise ConfigError(
                f"dds.peers[{i}]: {str(peer)!r} is not a loopback address, but dds.loopback_only keeps DDS "
                "on loopback"
            )
    return peers


def _domain(item: object, key: str) -> DomainConfig:
    if isinstance(item, int | str) and not isinstance(item, bool):  # an id, or one as a flag gives it
        item = {"id": item}
    if not isinstance(item, dict):
        raise ConfigError(f"{key}: expected a domain id or a mapping with id, got {item!r}")
    reject_unknown(item, key + ".", {"id", "robot_name"})
    domain_id = whole_number(item.get("id"), f"{key}.id", 0, 232, "a DDS domain id")
    name = item.get("robot_name")
    return DomainConfig(domain_id, None if name is None else string(name, f"{key}.robot_name"))
