"""The Zenoh session configuration built from the `zenoh:` section, on top of a native Zenoh file."""

from __future__ import annotations

import json

import zenoh

from overseer.config import ConfigError
from overseer.config.zenoh import ZenohConfig

# How long one attempt to reach a router may take in client mode before it is counted and retried.
CLIENT_CONNECT_TIMEOUT_MS = 5000
_RETRY = {"period_init_ms": 500, "period_max_ms": 4000, "period_increase_factor": 2}


def session_config(config: ZenohConfig) -> zenoh.Config:
    """The native file's configuration (if any) with the exporter's keys; ConfigError if unusable."""
    if config.config is not None:
        try:
            native = zenoh.Config.from_file(config.config)
        except (zenoh.ZError, OSError, ValueError) as error:
            raise ConfigError(
                f"zenoh.config: {config.config!r} is not a usable Zenoh configuration: {error}"
            ) from None
    else:
        native = zenoh.Config()
    mode = config.mode or (default_mode(config.connect) if config.config is None else None)
    if mode is not None:
        _insert(native, "mode", mode, "zenoh.mode")
    if config.connect:
        _insert(native, "connect/endpoints", list(config.connect), "zenoh.connect")
    if config.listen:
        _insert(native, "listen/endpoints", list(config.listen), "zenoh.listen")
    elif mode == "client":
        _insert(native, "listen/endpoints", [], "zenoh.listen")
    if config.config is None:
        _insert(native, "scouting/multicast/enabled", config.multicast_scouting, "zenoh.multicast_scouting")
    # A diagnostics array is over Zenoh's 3 kB threshold: with shared memory on, every sender on this host
    # would hand it over in a segment of its own pool, which the exporter would map and, while the ingest
    # is behind, hold.
    _insert(native, "transport/shared_memory/enabled", config.shared_memory, "zenoh.shared_memory")
    # The exporter must start, and serve, with no router reachable, and keep trying to reach one: a
    # client's first attempt is bounded (it is retried and counted by the source), a peer retries alone.
    _insert(native, "connect/timeout_ms", {"client": CLIENT_CONNECT_TIMEOUT_MS, "peer": -1}, "zenoh.connect")
    _insert(native, "connect/exit_on_failure", {"client": True, "peer": False}, "zenoh.connect")
    _insert(native, "connect/retry", _RETRY, "zenoh.connect")
    return native


def default_mode(connect: tuple[str, ...]) -> str:
    """Client of the one router given; peer with several, since a client keeps a link to one router only.

    Sites' routers need not know each other, so the exporter must hold a link to each of them; a peer
    connects to every endpoint it is given and keeps trying those it cannot reach.
    """
    return "peer" if len(connect) > 1 else "client"


def _insert(native: zenoh.Config, path: str, value: object, key: str) -> None:
    try:
        native.insert_json5(path, json.dumps(value))
    except (zenoh.ZError, ValueError) as error:
        raise ConfigError(f"{key}: Zenoh refuses {value!r}: {error}") from None
