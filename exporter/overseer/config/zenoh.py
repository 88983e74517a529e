"""The `zenoh:` section: routers to connect to, endpoints to listen on, and the key shapes to follow."""

from __future__ import annotations

import re
from dataclasses import dataclass, fields
from pathlib import Path
from typing import Any

from overseer.config.errors import ConfigError
from overseer.config.parsers import boolean, listed, string, whole_number

ZENOH_MODES = ("client", "peer")
ZENOH_KEY_FORMATS = ("rmw_zenoh", "bridge")
_ZENOH_ENDPOINT = re.compile(r"[a-z][a-z0-9-]*/\S+")


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


KEYS = {f.name for f in fields(ZenohConfig)}


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
    )
