"""Initial DDS peers: each configured host resolved once, at start, into the addresses Cyclone is given.

Cyclone aborts the whole process on a peer name it cannot resolve, so names are resolved here first: a
name that does not resolve is reported, skipped, and the rest of the peers (and the exporter) carry on.
Cyclone speaks IPv4 unless configured otherwise, so only IPv4 addresses are used.
"""

from __future__ import annotations

import socket
from collections.abc import Callable, Sequence

from overseer.config.dds import DdsPeer


def resolve_peer(peer: DdsPeer) -> list[str]:
    """The peer's IPv4 addresses as Cyclone takes them (`IP` or `IP:PORT`); OSError if it has none."""
    answers = socket.getaddrinfo(peer.host, None, family=socket.AF_INET, type=socket.SOCK_DGRAM)
    addresses = sorted({str(answer[4][0]) for answer in answers})
    if not addresses:
        raise OSError(f"no IPv4 address for {peer.host}")
    suffix = "" if peer.port is None else f":{peer.port}"
    return [address + suffix for address in addresses]


def peer_addresses(peers: Sequence[DdsPeer], on_unresolved: Callable[[DdsPeer, str], None]) -> list[str]:
    """Every address of every peer, in order and without repeats; `on_unresolved` hears of the failures."""
    addresses: list[str] = []
    for peer in peers:
        try:
            resolved = resolve_peer(peer)
        except (OSError, UnicodeError) as error:
            on_unresolved(peer, str(error))
            continue
        addresses.extend(address for address in resolved if address not in addresses)
    return addresses
