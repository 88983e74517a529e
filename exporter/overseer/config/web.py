"""The `web:` section: where the HTTP endpoint listens, its TLS and auth file, the URL users reach it at."""

from __future__ import annotations

import re
from dataclasses import dataclass, replace
from typing import Any

from overseer.config.errors import ConfigError
from overseer.config.options import Option, option
from overseer.config.parsers import boolean, string

DEFAULT_PORT = 9849
OPTIONS: tuple[Option, ...] = (
    option(
        "web.listen_address",
        f":{DEFAULT_PORT}",
        f"where to serve, HOST:PORT; :{DEFAULT_PORT} is every interface",
        metavar="HOST:PORT",
    ),
    option(
        "web.config_file",
        "none: plain HTTP",
        "TLS, client certificates and basic auth, in the format of Prometheus' exporter-toolkit",
        metavar="PATH",
        flag="--web.config.file",
    ),
    option(
        "web.external_url",
        "none: alerts link to http://<instance>",
        "the URL users reach the exporter at, for the status-page links in alerts (overseer_web_info)",
        metavar="URL",
    ),
    option(
        "web.enable_maintenance_api",
        "off",
        "let the users of maintenance.writers open and end maintenance windows (POST, DELETE "
        "/api/v1/maintenance) and retire robots (POST /api/v1/retirements); reading is always on",
        kind="switch",
    ),
    option(
        "web.enable_lifecycle",
        "off",
        "answer POST /-/reload (reload the inventory file), as Prometheus's flag of the same name does",
        kind="switch",
    ),
)
KEYS = {entry.key.partition(".")[2] for entry in OPTIONS}


@dataclass(frozen=True)
class WebConfig:
    """The HTTP endpoint; `config_file` is an exporter-toolkit web config (TLS, basic auth)."""

    listen_address: str = f":{DEFAULT_PORT}"
    config_file: str | None = None
    external_url: str | None = None  # the URL users reach us at, for links in alerts (no trailing /)
    enable_maintenance_api: bool = False  # POST and DELETE /api/v1/maintenance, for maintenance.writers
    enable_lifecycle: bool = False  # POST /-/reload

    @property
    def host_and_port(self) -> tuple[str, int]:
        """The address split into a bind host ('' for all interfaces) and a port."""
        return parse_listen_address(self.listen_address)


def parse_listen_address(value: str) -> tuple[str, int]:
    """Split `host:port` (host may be empty or a bracketed IPv6 address) into host and port."""
    host, sep, port = value.rpartition(":")
    if not sep or not port.isdigit() or not 0 <= int(port) <= 65535:
        raise ConfigError(f"web.listen_address: expected host:port, got {value!r}")
    return host.strip("[]"), int(port)


def web_config(raw: dict[str, Any]) -> WebConfig:
    """The section from its mapping."""
    config = WebConfig()
    if "listen_address" in raw:
        address = string(raw["listen_address"], "web.listen_address")
        parse_listen_address(address)
        config = replace(config, listen_address=address)
    if raw.get("config_file") is not None:
        config = replace(config, config_file=string(raw["config_file"], "web.config_file"))
    if raw.get("external_url") is not None:
        config = replace(config, external_url=_external_url(raw["external_url"]))
    if "enable_maintenance_api" in raw:
        enabled = boolean(raw["enable_maintenance_api"], "web.enable_maintenance_api")
        config = replace(config, enable_maintenance_api=enabled)
    if "enable_lifecycle" in raw:
        config = replace(config, enable_lifecycle=boolean(raw["enable_lifecycle"], "web.enable_lifecycle"))
    return config


def _external_url(value: object) -> str:
    url = string(value, "web.external_url")
    if not re.fullmatch(r"https?://[^/\s?#]+(/[^\s?#]*)?", url):
        raise ConfigError(f"web.external_url: expected http(s)://HOST[:PORT][/PATH], got {url!r}")
    return url.rstrip("/")
