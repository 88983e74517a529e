"""The `alertmanager:` section: the Alertmanager the exporter opens silences in for maintenance windows."""

from __future__ import annotations

import re
import ssl
from dataclasses import dataclass
from typing import Any

from overseer.config.errors import ConfigError
from overseer.config.options import Option, option
from overseer.config.parsers import parse_duration, read_text_file, reject_unknown, string

OPTIONS: tuple[Option, ...] = (
    option(
        "alertmanager.url",
        "none: no silences",
        "the Alertmanager to open a silence in for each maintenance window (its API v2)",
        metavar="URL",
    ),
    option("alertmanager.username", "none", "basic-auth user for Alertmanager", metavar="NAME"),
    option("alertmanager.password_file", "none", "a file whose first line is its password", metavar="PATH"),
    option(
        "alertmanager.ca_file", "the system's", "the CA to verify an https Alertmanager with", metavar="PATH"
    ),
    option(
        "alertmanager.timeout", "10s", "how long one request to Alertmanager may take", metavar="DURATION"
    ),
    option(
        "alertmanager.resync_interval",
        "1m",
        "how often the silences are compared with what Alertmanager holds (lost ones made again)",
        metavar="DURATION",
    ),
)
KEYS = {entry.key.partition(".")[2] for entry in OPTIONS}
_URL = re.compile(r"https?://[^/\s?#]+(/[^\s?#]*)?")


@dataclass(frozen=True)
class AlertmanagerConfig:
    """Where Alertmanager's API v2 is, and how to reach it (basic auth, a CA for https)."""

    url: str
    username: str = ""
    password: str = ""
    ca_file: str = ""
    timeout: float = 10.0
    resync_interval: float = 60.0  # how often the silences are compared with what Alertmanager holds

    def __repr__(self) -> str:
        """Everything but the password."""
        return f"AlertmanagerConfig(url={self.url!r}, username={self.username!r})"


def alertmanager_config(raw: dict[str, Any]) -> AlertmanagerConfig:
    """The section from its mapping."""
    reject_unknown(raw, "alertmanager.", KEYS)
    url = string(raw.get("url"), "alertmanager.url")
    if not _URL.fullmatch(url):
        raise ConfigError(f"alertmanager.url: expected http(s)://HOST[:PORT][/PATH], got {url!r}")
    username = string(raw["username"], "alertmanager.username") if "username" in raw else ""
    password = ""
    if "password_file" in raw:
        if not username:
            raise ConfigError("alertmanager.username: required with alertmanager.password_file")
        path = string(raw["password_file"], "alertmanager.password_file")
        text = read_text_file(path, "alertmanager.password_file")
        password = text.splitlines()[0] if text else ""
        if not password:
            raise ConfigError(f"alertmanager.password_file: {path!r} is empty")
    ca_file = string(raw["ca_file"], "alertmanager.ca_file") if "ca_file" in raw else ""
    if ca_file:
        try:
            ssl.create_default_context(cafile=ca_file)
        except (ssl.SSLError, OSError) as error:
            raise ConfigError(f"alertmanager.ca_file: cannot use {ca_file!r}: {error}") from None
    timeout = parse_duration(raw["timeout"], "alertmanager.timeout") if "timeout" in raw else 10.0
    resync = 60.0
    if "resync_interval" in raw:
        resync = parse_duration(raw["resync_interval"], "alertmanager.resync_interval")
        if resync < 1.0:
            raise ConfigError("alertmanager.resync_interval: at least 1s")
    return AlertmanagerConfig(url.rstrip("/"), username, password, ca_file, timeout, resync)
