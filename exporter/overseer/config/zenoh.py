"""The `zenoh:` section: routers to connect to, endpoints to listen on, and the key shapes to follow."""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from overseer.config.errors import ConfigError
from overseer.config.options import Option, option
from overseer.config.parsers import boolean, listed, string, whole_number

ZENOH_MODES = ("client", "peer")
ZENOH_KEY_FORMATS = ("rmw_zenoh", "bridge")
_ZENOH_ENDPOINT = re.compile(r"[a-z][a-z0-9-]*/\S+")
DEFAULT_QUEUE_LENGTH = 131_072  # 13 s of 10,000 robots at 1 Hz, their first look's backlog (~4 kB each)
MAX_QUEUE_LENGTH = 10_000_000


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
    queue_length: int = DEFAULT_QUEUE_LENGTH  # samples waiting (a subscription's; a worker's, relayed)
    shared_memory: bool = False  # take part in Zenoh's shared memory with sessions on the same host

    @property
    def unnamespaced_robot(self) -> str:
        """The robot name for `/diagnostics_agg` without a namespace."""
        return self.robot_name or f"domain{self.domain}"


OPTIONS: tuple[Option, ...] = (
    Option(
        "zenoh.enabled",
        "off; any zenoh key or flag turns it on",
        "follow robots over Zenoh (false in the file keeps the section but off)",
        file_only="any --zenoh.* flag turns Zenoh on",
    ),
    option(
        "zenoh.mode",
        "client with one connect, peer with several",
        "the exporter's Zenoh session mode, client or peer (a client keeps a link to one router only; a "
        "peer holds one to each site's router)",
        metavar="MODE",
    ),
    option(
        "zenoh.connect",
        "none",
        "a Zenoh router (or peer) to connect to, e.g. tcp/router.example:7447; repeat for several",
        kind="repeated",
        metavar="ENDPOINT",
    ),
    option(
        "zenoh.listen",
        "none",
        "a Zenoh endpoint to listen on (robots connect to the exporter), e.g. tcp/0.0.0.0:7447; repeatable",
        kind="repeated",
        metavar="ENDPOINT",
    ),
    option(
        "zenoh.domain", "0", "the ROS domain of the rmw_zenoh keys (ROS_DOMAIN_ID of the robots)", metavar="N"
    ),
    option(
        "zenoh.config",
        "none",
        "a native Zenoh JSON5 configuration (TLS, mTLS, access control, anything else of Zenoh's)",
        metavar="FILE",
    ),
    option(
        "zenoh.key_formats",
        "rmw_zenoh, bridge",
        "a key format to follow: rmw_zenoh's keys, or zenoh-bridge-ros2dds's (bridge); repeat for both",
        kind="repeated",
        metavar="FORMAT",
        flag="--zenoh.key-format",
    ),
    option(
        "zenoh.robot_name",
        "domain<ID>: robots by their nodes' namespaces",
        "name the one robot of un-namespaced topics, whatever its nodes' namespaces",
        metavar="NAME",
    ),
    option(
        "zenoh.multicast_scouting",
        "false",
        "find routers and peers by multicast scouting too (true or false)",
        metavar="BOOL",
    ),
    option(
        "zenoh.queue_length",
        f"{DEFAULT_QUEUE_LENGTH}",
        "samples that may wait for the ingest while it is behind, as in a large fleet's first seconds: "
        "copied out of Zenoh between shares of the ingest's work, they wait for it (per data "
        "subscription of the session, two per key format; per ingest worker, with several), and beyond "
        "it are dropped and counted as dropped. Each holds its "
        "payload while it waits (about 4 kB at 50 components): the memory it may take is this many times "
        "the largest sample. Zenoh's own channel of each subscription has the same bound (beyond it the "
        "router drops what does not fit, counted as lost where rmw_zenoh numbers it), but is kept short",
        metavar="N",
    ),
    option(
        "zenoh.shared_memory",
        "false",
        "take part in Zenoh's shared memory with routers and robots on the same host (true or false; this "
        "setting wins over the zenoh.config file's). Off, their samples come over the link: with it, the "
        "exporter maps each sender's pool (16 MB a session), and samples waiting for a busy ingest hold "
        "the sender's buffers",
        metavar="BOOL",
    ),
)
KEYS = {entry.key.partition(".")[2] for entry in OPTIONS}


def zenoh_config(raw: dict[str, Any]) -> ZenohConfig:
    """The section from its mapping; any Zenoh key turns the transport on, unless `enabled` says otherwise."""
    defaults = ZenohConfig()
    mode = raw.get("mode", defaults.mode)
    if mode is not None and mode not in ZENOH_MODES:
        raise ConfigError(f"zenoh.mode: expected client or peer, got {mode!r}")
    endpoints: dict[str, tuple[str, ...]] = {}
    for key in ("connect", "listen"):
        values = raw.get(key, [])
        items = tuple(string(v, f"zenoh.{key}") for v in (values if isinstance(values, list) else [values]))
        for endpoint in items:
            if not _ZENOH_ENDPOINT.fullmatch(endpoint):
                raise ConfigError(
                    f"zenoh.{key}: expected an endpoint such as tcp/host:7447, got {endpoint!r}"
                )
        endpoints[key] = items
    domain = whole_number(raw.get("domain", defaults.domain), "zenoh.domain", 0, 232, "a ROS domain id")
    formats = defaults.key_formats
    if "key_formats" in raw:
        formats = tuple(
            string(f, "zenoh.key_formats") for f in listed(raw["key_formats"], "zenoh.key_formats")
        )
        for name in formats:
            if name not in ZENOH_KEY_FORMATS:
                raise ConfigError(f"zenoh.key_formats: expected rmw_zenoh or bridge, got {name!r}")
        if not formats:
            raise ConfigError("zenoh.key_formats: expected at least one of rmw_zenoh, bridge, got []")
    file = raw.get("config")
    if file is not None and not Path(string(file, "zenoh.config")).is_file():
        raise ConfigError(f"zenoh.config: cannot read {file!r}: no such file")
    robot_name = raw.get("robot_name")
    queue_length = whole_number(
        raw.get("queue_length", defaults.queue_length),
        "zenoh.queue_length",
        1,
        MAX_QUEUE_LENGTH,
        "a number of samples",
    )
    return ZenohConfig(
        enabled=boolean(raw.get("enabled", bool(raw)), "zenoh.enabled"),
        mode=mode,
        connect=endpoints["connect"],
        listen=endpoints["listen"],
        domain=domain,
        config=file,
        key_formats=formats,
        robot_name=None if robot_name is None else string(robot_name, "zenoh.robot_name"),
        multicast_scouting=boolean(
            raw.get("multicast_scouting", defaults.multicast_scouting), "zenoh.multicast_scouting"
        ),
        queue_length=queue_length,
        shared_memory=boolean(raw.get("shared_memory", defaults.shared_memory), "zenoh.shared_memory"),
    )
