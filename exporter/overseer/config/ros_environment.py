"""ROS's own environment variables as defaults of the ROS 2 transports, as every ROS 2 node reads them.

`ROS_DOMAIN_ID` is the domain; `ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST` (or `OFF`, or the older
`ROS_LOCALHOST_ONLY=1`) keeps DDS on loopback; `ROS_STATIC_PEERS` (hosts separated by `;`) adds DDS peers.
A key set by a flag or in the configuration file wins over the environment, which wins over the default;
`describe_origins` says where each value came from, for the log at start.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from overseer.config.dds import parse_dds_peer
from overseer.config.errors import ConfigError

DOMAIN_ID = "ROS_DOMAIN_ID"
DISCOVERY_RANGE = "ROS_AUTOMATIC_DISCOVERY_RANGE"
LOCALHOST_ONLY = "ROS_LOCALHOST_ONLY"
STATIC_PEERS = "ROS_STATIC_PEERS"
_RANGES = ("SUBNET", "LOCALHOST", "OFF", "SYSTEM_DEFAULT")
# The keys the environment may give a default to, and in which section each lives.
ROS_KEYS = ("dds.domains", "dds.loopback_only", "dds.peers", "zenoh.domain", "ros2.domain")


@dataclass(frozen=True)
class Origin:
    """Where one setting's value came from: a flag, the configuration file, a variable, or the default."""

    key: str
    source: str  # "flag", "config file", "ROS_DOMAIN_ID=7", "default"


def ros_defaults(environ: Mapping[str, str]) -> dict[str, tuple[Any, str]]:
    """Dotted key → (raw value, the variable it came from), for what ROS's variables in `environ` set."""
    found: dict[str, tuple[Any, str]] = {}
    domain_text = environ.get(DOMAIN_ID, "").strip()
    if domain_text:
        if not domain_text.isdigit() or not 0 <= int(domain_text) <= 232:
            raise ConfigError(f"{DOMAIN_ID}: expected a domain id from 0 to 232, got {domain_text!r}")
        domain = int(domain_text)
        source = f"{DOMAIN_ID}={domain}"
        found["dds.domains"] = ([domain], source)
        found["zenoh.domain"] = (domain, source)
        found["ros2.domain"] = (domain, source)
    discovery = environ.get(DISCOVERY_RANGE, "").strip().upper()
    if discovery and discovery not in _RANGES:
        raise ConfigError(f"{DISCOVERY_RANGE}: expected one of {', '.join(_RANGES)}, got {discovery!r}")
    if discovery in ("LOCALHOST", "OFF"):
        found["dds.loopback_only"] = (True, f"{DISCOVERY_RANGE}={discovery}")
    elif not discovery and environ.get(LOCALHOST_ONLY, "").strip() == "1":
        found["dds.loopback_only"] = (True, f"{LOCALHOST_ONLY}=1")
    peers = [peer.strip() for peer in environ.get(STATIC_PEERS, "").split(";") if peer.strip()]
    for index, peer in enumerate(peers):
        parsed = parse_dds_peer(peer, f"{STATIC_PEERS}[{index}]")
        if "dds.loopback_only" in found and not parsed.is_loopback:
            raise ConfigError(
                f"{STATIC_PEERS}: {peer!r} is not on this host, but {found['dds.loopback_only'][1]} keeps "
                "discovery on it"
            )
    if peers:
        found["dds.peers"] = (peers, f"{STATIC_PEERS}={';'.join(peers)}")
    return found


def apply_ros_defaults(
    raw: dict[str, Any], flags: set[str], environ: Mapping[str, str]
) -> tuple[Origin, ...]:
    """Fill `raw` (the file's mapping with the flags applied) from ROS's variables where neither set a key.

    `flags` are the dotted keys given on the command line. A section the environment would switch on
    by itself (Zenoh, ROS 2: any key of theirs enables them) only takes the default when it is there.
    """
    defaults = ros_defaults(environ)
    origins = []
    for dotted in ROS_KEYS:
        section, _, key = dotted.partition(".")
        mapping = raw.get(section)
        given = isinstance(mapping, dict) and key in mapping
        if dotted in flags:
            origins.append(Origin(dotted, "flag"))
        elif given:
            origins.append(Origin(dotted, "config file"))
        elif dotted in defaults and (isinstance(mapping, dict) or (section == "dds" and mapping is None)):
            value, source = defaults[dotted]
            if mapping is None:
                mapping = raw[section] = {}
            mapping[key] = value
            origins.append(Origin(dotted, source))
        else:
            origins.append(Origin(dotted, "default"))
    return tuple(origins)
