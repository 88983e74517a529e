"""The `--web.config.file` of Prometheus' exporter-toolkit: TLS, client certificates and basic auth.

Operators reuse the file their other exporters read. It is read and validated once, at start; every
error names the key and the bad value. Keys Overseer cannot honour (cipher and curve lists, SAN
allow-lists, inline certificates, rate limits) are refused rather than silently ignored, so a file
never promises a protection it does not give. Paths are relative to the file's directory, as in the
toolkit. Basic auth covers every path, /-/healthy included, as in the toolkit.
"""

from __future__ import annotations

import binascii
import hashlib
import hmac
import os
import re
import ssl
import threading
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import bcrypt
import yaml

from overseer.config import ConfigError
from overseer.config.parsers import read_text_file

REALM = "overseer"

CLIENT_AUTH_TYPES = {
    "NoClientCert": ssl.CERT_NONE,
    "VerifyClientCertIfGiven": ssl.CERT_OPTIONAL,
    "RequireAndVerifyClientCert": ssl.CERT_REQUIRED,
}
# Go accepts these, but Python's ssl verifies every client certificate it asks for.
_UNVERIFIED_CLIENT_AUTH_TYPES = ("RequestClientCert", "RequireAnyClientCert")
TLS_VERSIONS = {"TLS12": ssl.TLSVersion.TLSv1_2, "TLS13": ssl.TLSVersion.TLSv1_3}
_OLD_TLS_VERSIONS = ("TLS10", "TLS11")

# Response headers the toolkit lets a file set, and the values it accepts where it restricts them.
HEADER_VALUES: dict[str, tuple[str, ...] | None] = {
    "Content-Security-Policy": None,
    "X-Frame-Options": ("deny", "sameorigin"),
    "X-Content-Type-Options": ("nosniff",),
    "X-XSS-Protection": None,
    "Strict-Transport-Security": None,
}

_TLS_KEYS = {"cert_file", "key_file", "client_auth_type", "client_ca_file", "min_version", "max_version"}
_TLS_REFUSED = {
    "cert": "give the certificate as cert_file",
    "key": "give the key as key_file",
    "client_ca": "give the client CA as client_ca_file",
    "client_allowed_sans": "no SAN allow-lists; give such clients a CA of their own",
    "cipher_suites": "OpenSSL's default cipher suites apply",
    "curve_preferences": "OpenSSL's default curves apply",
}
_BCRYPT_HASH = re.compile(r"\$2[aby]\$(0[4-9]|[12]\d|3[01])\$[./A-Za-z0-9]{53}")
_MAX_BCRYPT_PASSWORD_BYTES = 72


class BasicAuth:
    """Users and their bcrypt hashes; verifies `Authorization` headers, caching successes.

    bcrypt is slow by design (about 70 ms at cost 10), and a scraper sends the same credentials every few
    seconds, so a verified password is remembered per user as a salted SHA-256 digest and compared in
    constant time. An unknown user costs a bcrypt of a dummy hash, so timing does not reveal user names.
    """

    def __init__(self, users: Mapping[str, bytes]) -> None:
        """Check passwords against `users` (user name → bcrypt hash)."""
        self.users = dict(users)
        cost = max(int(hashed[4:6]) for hashed in self.users.values())
        self._dummy_hash = bcrypt.hashpw(os.urandom(16).hex().encode(), bcrypt.gensalt(rounds=cost))
        self._salt = os.urandom(16)
        self._verified: dict[str, bytes] = {}  # at most one digest per configured user
        self._lock = threading.Lock()

    def user(self, header: str | None) -> str | None:
        """The configured user whose password `header` carries, or None."""
        credentials = _basic_credentials(header)
        return credentials[0] if credentials is not None and self.check(header) else None

    def check(self, header: str | None) -> bool:
        """True when `header` (an Authorization header's value) carries a configured user's password."""
        credentials = _basic_credentials(header)
        if credentials is None:
            return False
        user, password = credentials
        digest = hashlib.sha256(self._salt + password).digest()
        with self._lock:
            remembered = self._verified.get(user)
        if remembered is not None and hmac.compare_digest(remembered, digest):
            return True
        if len(password) > _MAX_BCRYPT_PASSWORD_BYTES:
            return False  # bcrypt would ignore the rest; the toolkit's Go bcrypt refuses such passwords too
        hashed = self.users.get(user)
        if bcrypt.checkpw(password, hashed or self._dummy_hash) and hashed is not None:
            with self._lock:
                self._verified[user] = digest
            return True
        return False


@dataclass(frozen=True)
class WebSecurity:
    """What the endpoint enforces: TLS (None for plain HTTP), basic auth (None for none), extra headers."""

    tls: ssl.SSLContext | None = None
    basic_auth: BasicAuth | None = None
    headers: tuple[tuple[str, str], ...] = ()

    def authorized(self, header: str | None) -> bool:
        """True when no basic auth is configured or `header` carries valid credentials."""
        return self.basic_auth is None or self.basic_auth.check(header)

    def user(self, header: str | None) -> str | None:
        """The basic-auth user `header` proves to be, or None (no basic auth configured, or no valid user)."""
        return None if self.basic_auth is None else self.basic_auth.user(header)


def load_web_config(path: str | Path | None) -> WebSecurity:
    """Read and validate the web config file at `path` (None: plain HTTP, no auth); ConfigError if bad."""
    if path is None:
        return WebSecurity()
    text = read_text_file(path, "web.config_file")
    try:
        raw = yaml.safe_load(text)
    except (yaml.YAMLError, ValueError, RecursionError) as error:  # also huge integers, deep nesting
        # PyYAML quotes the offending line, which may hold a password hash: name only the place.
        mark = getattr(error, "problem_mark", None)
        where = f" (line {mark.line + 1}, column {mark.column + 1})" if mark is not None else ""
        raise ConfigError(f"web.config_file: {str(path)!r} is not valid YAML{where}") from None
    try:
        return web_security_from_dict(raw, Path(path).parent)
    except ConfigError as error:
        raise ConfigError(f"web.config_file {str(path)!r}: {error}") from None


def web_security_from_dict(raw: object, directory: Path) -> WebSecurity:
    """Validate a parsed web config; relative paths are taken from `directory`."""
    if raw is None:
        return WebSecurity()
    document = _mapping(raw, "top level")
    _reject_unknown(document, "", {"tls_server_config", "http_server_config", "basic_auth_users"})
    tls = _tls_context(_mapping(document.get("tls_server_config") or {}, "tls_server_config"), directory)
    headers = _headers(_mapping(document.get("http_server_config") or {}, "http_server_config"))
    users = _users(_mapping(document.get("basic_auth_users") or {}, "basic_auth_users"))
    return WebSecurity(tls, BasicAuth(users) if users else None, headers)


def _tls_context(raw: dict[str, Any], directory: Path) -> ssl.SSLContext | None:
    for key, reason in _TLS_REFUSED.items():
        if key in raw:
            raise ConfigError(f"tls_server_config.{key}: not supported by Overseer ({reason})")
    _reject_unknown(raw, "tls_server_config.", _TLS_KEYS)
    if not raw:
        return None
    cert_file = _path(raw.get("cert_file"), "tls_server_config.cert_file", directory)
    key_file = _path(raw.get("key_file"), "tls_server_config.key_file", directory)
    auth_type = raw.get("client_auth_type", "NoClientCert")
    if auth_type in _UNVERIFIED_CLIENT_AUTH_TYPES:
        raise ConfigError(
            f"tls_server_config.client_auth_type: {auth_type!r} (a certificate nobody verifies) is not "
            "supported; use VerifyClientCertIfGiven or RequireAndVerifyClientCert"
        )
    if not isinstance(auth_type, str) or auth_type not in CLIENT_AUTH_TYPES:
        raise ConfigError(
            f"tls_server_config.client_auth_type: expected one of {', '.join(CLIENT_AUTH_TYPES)}, "
            f"got {auth_type!r}"
        )
    min_version = _tls_version(raw, "min_version", "TLS12")
    max_version = _tls_version(raw, "max_version", "TLS13")
    if max_version < min_version:
        raise ConfigError(
            f"tls_server_config.max_version: must not be below min_version, got {raw['max_version']!r}"
        )
    context = ssl.SSLContext(ssl.PROTOCOL_TLS_SERVER)
    context.minimum_version, context.maximum_version = min_version, max_version
    context.set_alpn_protocols(["http/1.1"])
    try:
        context.load_cert_chain(cert_file, key_file)
    except OSError as error:  # ssl.SSLError is one
        raise ConfigError(
            f"tls_server_config.cert_file, key_file: cannot load {cert_file!r} with {key_file!r}: "
            f"{_reason(error)}"
        ) from None
    ca_file = raw.get("client_ca_file")
    if auth_type == "NoClientCert":
        if ca_file is not None:
            raise ConfigError(
                "tls_server_config.client_ca_file: set, but client_auth_type is NoClientCert; "
                "use VerifyClientCertIfGiven or RequireAndVerifyClientCert"
            )
        return context
    client_ca_file = _path(ca_file, "tls_server_config.client_ca_file", directory)
    try:
        context.load_verify_locations(cafile=client_ca_file)
    except OSError as error:  # ssl.SSLError is one
        raise ConfigError(
            f"tls_server_config.client_ca_file: cannot load {client_ca_file!r}: {_reason(error)}"
        ) from None
    context.verify_mode = CLIENT_AUTH_TYPES[auth_type]
    return context


def _tls_version(raw: dict[str, Any], key: str, default: str) -> ssl.TLSVersion:
    value = raw.get(key, default)
    if isinstance(value, str) and value in _OLD_TLS_VERSIONS:
        raise ConfigError(f"tls_server_config.{key}: {value} is not supported; use TLS12 or TLS13")
    if not isinstance(value, str) or value not in TLS_VERSIONS:
        raise ConfigError(f"tls_server_config.{key}: expected TLS12 or TLS13, got {value!r}")
    return TLS_VERSIONS[value]


def _headers(raw: dict[str, Any]) -> tuple[tuple[str, str], ...]:
    _reject_unknown(raw, "http_server_config.", {"http2", "headers"})
    if "http2" in raw and not isinstance(raw["http2"], bool):
        raise ConfigError(f"http_server_config.http2: expected true or false, got {raw['http2']!r}")
    headers = _mapping(raw.get("headers") or {}, "http_server_config.headers")
    result = []
    for name, value in headers.items():
        key = f"http_server_config.headers.{_shown(name)}"
        if name not in HEADER_VALUES:
            raise ConfigError(f"{key}: cannot be set (expected one of {', '.join(HEADER_VALUES)})")
        if value is None or value == "":
            continue  # blank means unset, as in the toolkit
        if not isinstance(value, str) or any(c in value for c in "\r\n\0"):
            raise ConfigError(f"{key}: expected a one-line string, got {value!r}")
        allowed = HEADER_VALUES[name]
        if allowed is not None and value.lower() not in allowed:
            raise ConfigError(f"{key}: expected one of {', '.join(allowed)}, got {value!r}")
        result.append((name, value))
    return tuple(result)


def _users(raw: dict[str, Any]) -> dict[str, bytes]:
    users = {}
    for user, hashed in raw.items():
        if not isinstance(user, str) or not user or ":" in user:
            raise ConfigError(f"basic_auth_users: expected user names without ':', got {user!r}")
        if not isinstance(hashed, str) or not _valid_bcrypt_hash(hashed):
            # The value is a secret: say what is wrong, never echo it.
            raise ConfigError(
                f"basic_auth_users.{_shown(user)}: expected a bcrypt hash such as $2y$10$... "
                "(htpasswd -nBC 10 \"\" | tr -d ':\\n')"
            )
        users[user] = hashed.encode("ascii")
    return users


def _valid_bcrypt_hash(hashed: str) -> bool:
    if not _BCRYPT_HASH.fullmatch(hashed):
        return False
    try:  # the salt must decode; hashing with it at the lowest cost (about 1 ms) tells
        bcrypt.hashpw(b"", f"{hashed[:4]}04${hashed[7:29]}".encode("ascii"))
    except ValueError:
        return False
    return True


def _basic_credentials(header: str | None) -> tuple[str, bytes] | None:
    if header is None:
        return None
    scheme, _, token = header.strip().partition(" ")
    if scheme.lower() != "basic":
        return None
    try:
        decoded = binascii.a2b_base64(token.strip().encode("ascii"), strict_mode=True)
    except (binascii.Error, UnicodeEncodeError):
        return None
    user, separator, password = decoded.partition(b":")
    if not separator:
        return None
    try:
        return user.decode("utf-8"), password
    except UnicodeDecodeError:
        return None


def _path(value: object, key: str, directory: Path) -> str:
    if not isinstance(value, str) or not value or "\0" in value:
        raise ConfigError(f"{key}: expected a file name, got {value!r}")
    return str(directory / value)


def _mapping(value: object, key: str) -> dict[str, Any]:
    if not isinstance(value, dict):
        raise ConfigError(f"{key}: expected a mapping, got {value!r}")
    return value


def _reject_unknown(raw: dict[str, Any], prefix: str, allowed: set[str]) -> None:
    for key in raw:
        if key not in allowed:
            raise ConfigError(
                f"{prefix}{_shown(key)}: unknown key (expected one of {', '.join(sorted(allowed))})"
            )


def _shown(key: object) -> str:
    """A key as an error message names it: as written when printable, else quoted with escapes."""
    return key if isinstance(key, str) and key.isprintable() and key else repr(key)


def _reason(error: OSError) -> str:
    if isinstance(error, ssl.SSLError):
        return str(error.reason or error)
    return str(error.strerror or error)
