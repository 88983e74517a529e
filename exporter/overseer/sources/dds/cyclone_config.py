"""Cyclone DDS configuration: the loopback-only document and the process's configured domains."""

from __future__ import annotations

import threading
from collections.abc import Sequence

from cyclonedds.domain import Domain

LOOPBACK_MAX_PARTICIPANTS = 60

_domains: dict[int, tuple[str, Domain]] = {}
_lock = threading.Lock()


def loopback_only_config() -> str:
    """A Cyclone DDS configuration that keeps all traffic on the loopback interface.

    Loopback has no multicast, so discovery goes by unicast to 127.0.0.1, probing the participant
    indices that local processes take (the same port formula Fast DDS uses for its initial peers).
    """
    return (
        '<CycloneDDS><Domain id="any">'
        '<General><Interfaces><NetworkInterface name="lo"/></Interfaces>'
        "<AllowMulticast>false</AllowMulticast></General>"
        "<Discovery><ParticipantIndex>auto</ParticipantIndex>"
        f"<MaxAutoParticipantIndex>{LOOPBACK_MAX_PARTICIPANTS}</MaxAutoParticipantIndex>"
        '<Peers><Peer address="127.0.0.1"/></Peers></Discovery>'
        # Key hashes let Fast DDS writers notice at once when our readers leave.
        "<Internal><GenerateKeyhash>true</GenerateKeyhash></Internal>"
        "</Domain></CycloneDDS>"
    )


def peers_config(addresses: Sequence[str], max_participant_index: int) -> str:
    """A Cyclone DDS fragment sending discovery to `addresses` (`IP` or `IP:PORT`) for as long as we run.

    An address without a port is probed at the discovery port of every participant index from 0 to
    `max_participant_index`, since Cyclone and Fast DDS give each DDS process on a host an index of its
    own, lowest free first. Cyclone stops probing a configured peer that has not answered within 30 s
    (InitialLocatorPruneDelay); robots boot after the exporter and WiFi drops out, so these peers are
    kept for good. With peers configured, Cyclone takes a participant index itself, so a robot that
    lists this host as its peer finds it too. Empty when there are no addresses.
    """
    if not addresses:
        return ""
    peers = "".join(f'<Peer address="{address}" PruneDelay="inf"/>' for address in addresses)
    return (
        '<CycloneDDS><Domain id="any"><Discovery>'
        f"<MaxAutoParticipantIndex>{max_participant_index}</MaxAutoParticipantIndex>"
        f"<Peers>{peers}</Peers></Discovery></Domain></CycloneDDS>"
    )


def configure_domain(domain_id: int, config: str, *, keep_existing: bool = False) -> None:
    """Give `domain_id` the Cyclone `config` (XML or URI) for the rest of this process.

    Cyclone accepts one explicit configuration per domain and process. Asking for a different one is
    an error, unless `keep_existing` says the one already there will do (the simulator of
    `overseer demo` joins the domain the exporter configured).
    """
    with _lock:
        existing = _domains.get(domain_id)
        if existing is None:
            _domains[domain_id] = (config, Domain(domain_id, config))
        elif existing[0] != config and not keep_existing:
            raise ValueError(f"DDS domain {domain_id} is already configured differently in this process")
