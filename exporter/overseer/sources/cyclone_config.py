"""Cyclone DDS configuration documents."""

from __future__ import annotations

LOOPBACK_MAX_PARTICIPANTS = 60


def loopback_only_config() -> str:
    """A Cyclone DDS configuration that keeps all traffic on the loopback interface.

    Loopback has no multicast, so discovery goes by unicast to 127.0.0.1, probing the participant
    indices that local processes take (the same port formula Fast DDS uses for its initial peers).
    """
    return (
        '<CycloneDDS><Domain id="any">'
        "<General><Interfaces><NetworkInterface name=\"lo\"/></Interfaces>"
        "<AllowMulticast>false</AllowMulticast></General>"
        "<Discovery><ParticipantIndex>auto</ParticipantIndex>"
        f"<MaxAutoParticipantIndex>{LOOPBACK_MAX_PARTICIPANTS}</MaxAutoParticipantIndex>"
        '<Peers><Peer address="127.0.0.1"/></Peers></Discovery>'
        "</Domain></CycloneDDS>"
    )
