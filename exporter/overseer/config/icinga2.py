"""The `icinga2:` section of the configuration: where and how to push, validated at start.

Secrets come only from files (`password_file`, `client_key`); every file is read here, once, so an
unreadable one stops the exporter at start with the key and the path named.
"""

from __future__ import annotations

import re
import ssl
from dataclasses import dataclass
from typing import Any

from overseer.config.errors import ConfigError
from overseer.config.options import Option, option
from overseer.config.parsers import parse_duration, read_text_file

SERVICE_KINDS = ("robot", "groups")
OPTIONS: tuple[Option, ...] = (
    option(
        "icinga2.url",
        "none: no push",
        "push robots and results to this Icinga 2 API, e.g. https://icinga.example:5665",
        metavar="URL",
    ),
    option("icinga2.username", "none", "the Icinga 2 ApiUser", metavar="NAME"),
    option(
        "icinga2.password_file", "none", "a file whose first line is the ApiUser's password", metavar="PATH"
    ),
    option("icinga2.ca_file", "required", "the CA certificate of the Icinga 2 API", metavar="PATH"),
    option(
        "icinga2.tls_server_name",
        "the URL's host",
        "the name in the Icinga 2 API's certificate, when not the URL's host",
        metavar="NAME",
    ),
    option("icinga2.client_cert", "none", "a client certificate instead of a password", metavar="PATH"),
    option("icinga2.client_key", "none", "the client certificate's key", metavar="PATH"),
    option(
        "icinga2.interval",
        "60s",
        "push every robot's results this often, and at once on a change; Icinga trusts a result for two",
        metavar="DURATION",
    ),
    option("icinga2.timeout", "10s", "how long one request to Icinga 2 may take", metavar="DURATION"),
    option(
        "icinga2.services",
        "robot, groups",
        "a kind of service to push: robot (one per robot) or groups (one per component group); repeat",
        kind="repeated",
        metavar="KIND",
        flag="--icinga2.service",
    ),
    option("icinga2.host_template", "none", "a host template the robots' hosts import", metavar="NAME"),
    option("icinga2.service_template", "none", "a service template the services import", metavar="NAME"),
    option("icinga2.zone", "none", "the zone the hosts and services are made in", metavar="ZONE"),
    option(
        "icinga2.exporter_id",
        "overseer",
        "the mark on the objects this exporter makes (vars.overseer_exporter): two exporters, two ids",
        metavar="ID",
    ),
)
KEYS = {entry.key.partition(".")[2] for entry in OPTIONS}
_URL = re.compile(r"https://(\[[0-9A-Fa-f:.]+\]|[^/\s:\[\]]+)(?::(\d{1,5}))?/?")


@dataclass(frozen=True)
class Icinga2Config:
    """Where the Icinga 2 REST API is, how to authenticate, and what to push how often."""

    url: str
    host: str
    port: int
    ca_file: str
    username: str = ""
    password: str = ""
    tls_server_name: str = ""
    client_cert: str = ""
    client_key: str = ""
    interval: float = 60.0
    timeout: float = 10.0
    services: tuple[str, ...] = SERVICE_KINDS
    host_template: str = ""
    service_template: str = ""
    zone: str = ""
    exporter_id: str = "overseer"

    def __repr__(self) -> str:
        """Everything but the password."""
        return (
            f"Icinga2Config(url={self.url!r}, username={self.username!r}, exporter_id={self.exporter_id!r})"
        )

    @property
    def ttl(self) -> float:
        """How long Icinga trusts a pushed result: two intervals, so one lost push is not an alarm."""
        return 2 * self.interval


def icinga2_config(raw: object) -> Icinga2Config:
    """Validate the `icinga2:` mapping; ConfigError naming the key and the value otherwise."""
    if not isinstance(raw, dict):
        raise ConfigError(f"icinga2: expected a mapping, got {raw!r}")
    for key in raw:
        if key not in KEYS:
            shown = key if isinstance(key, str) and key.isprintable() and key else repr(key)
            raise ConfigError(f"icinga2.{shown}: unknown key (expected one of {', '.join(sorted(KEYS))})")
    url = _text(raw, "url", required=True)
    match = _URL.fullmatch(url)
    if match is None:
        raise ConfigError(f"icinga2.url: expected https://HOST:PORT (the API, port 5665), got {url!r}")
    port = int(match.group(2) or 5665)
    if not 0 < port < 65536:
        raise ConfigError(f"icinga2.url: port must be 1 to 65535, got {url!r}")
    ca_file = _text(raw, "ca_file", required=True)
    _load_ca(ca_file)
    username = _text(raw, "username")
    password_file = _text(raw, "password_file")
    client_cert = _text(raw, "client_cert")
    client_key = _text(raw, "client_key")
    password = ""
    if password_file:
        if not username:
            raise ConfigError("icinga2.username: required with icinga2.password_file")
        password = _read_secret(password_file)
    elif username:
        raise ConfigError("icinga2.password_file: required with icinga2.username")
    if client_key and not client_cert:
        raise ConfigError("icinga2.client_cert: required with icinga2.client_key")
    if client_cert:
        _load_client_cert(client_cert, client_key)
    if not password and not client_cert:
        raise ConfigError(
            "icinga2: give username and password_file, or client_cert (and client_key), to authenticate"
        )
    services = _services(raw.get("services", list(SERVICE_KINDS)))
    interval = parse_duration(raw["interval"], "icinga2.interval") if "interval" in raw else 60.0
    timeout = parse_duration(raw["timeout"], "icinga2.timeout") if "timeout" in raw else 10.0
    return Icinga2Config(
        url=url.rstrip("/"),
        host=match.group(1).strip("[]"),
        port=port,
        ca_file=ca_file,
        username=username,
        password=password,
        tls_server_name=_text(raw, "tls_server_name"),
        client_cert=client_cert,
        client_key=client_key,
        interval=interval,
        timeout=timeout,
        services=services,
        host_template=_text(raw, "host_template"),
        service_template=_text(raw, "service_template"),
        zone=_text(raw, "zone"),
        exporter_id=_text(raw, "exporter_id") or "overseer",
    )


def _text(raw: dict[str, Any], key: str, required: bool = False) -> str:
    value = raw.get(key)
    if value is None and not required:
        return ""
    if not isinstance(value, str) or not value:
        raise ConfigError(f"icinga2.{key}: expected a non-empty string, got {value!r}")
    return value


def _services(value: object) -> tuple[str, ...]:
    if not isinstance(value, list) or not value:
        raise ConfigError(f"icinga2.services: expected a non-empty list of robot, groups; got {value!r}")
    for item in value:
        if item not in SERVICE_KINDS:
            raise ConfigError(f"icinga2.services: expected robot or groups, got {item!r}")
    return tuple(kind for kind in SERVICE_KINDS if kind in value)


def _read_secret(path: str) -> str:
    text = read_text_file(path, "icinga2.password_file")
    password = text.splitlines()[0] if text else ""
    if not password:
        raise ConfigError(f"icinga2.password_file: {path!r} is empty")  # never echo the content
    return password


def _load_ca(path: str) -> None:
    try:
        ssl.create_default_context(cafile=path)
    except ssl.SSLError as error:  # before OSError, its base class
        raise ConfigError(f"icinga2.ca_file: {path!r} holds no usable certificate: {error.reason}") from None
    except OSError as error:
        raise ConfigError(f"icinga2.ca_file: cannot read {path!r}: {error.strerror}") from None


def _load_client_cert(cert: str, key: str) -> None:
    context = ssl.SSLContext(ssl.PROTOCOL_TLS_CLIENT)
    try:
        context.load_cert_chain(cert, key or None)
    except ssl.SSLError as error:  # before OSError, its base class
        raise ConfigError(
            f"icinga2.client_cert: {cert!r} (key {key or cert!r}) is not a usable certificate and key: "
            f"{error.reason}"
        ) from None
    except OSError as error:
        raise ConfigError(
            f"icinga2.client_cert: cannot read {cert!r} or {key or cert!r}: {error.strerror}"
        ) from None
