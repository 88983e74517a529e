"""Zenoh key expressions of ROS 2 diagnostics: rmw_zenoh's data keys and liveliness tokens, the bridge's keys.

rmw_zenoh (ROS 2 Jazzy, `rmw_zenoh_cpp`) publishes topic `/<ns>/diagnostics_agg` on
`<domain>/<ns>/diagnostics_agg/<DDS type name>/<type hash>` and declares, for each publisher, a liveliness
token `@ros2_lv/<domain>/<zid>/<nid>/<id>/MP/<enclave>/<ns>/<node>/<topic>/<type>/<hash>/<qos>` in which
every name has its `/` written as `%`. zenoh-bridge-ros2dds routes DDS topic `/<ns>/diagnostics_agg` as
key `<ns>/diagnostics_agg`, with no type and no hash, and declares, while a node on the robot publishes
it, the token `@/<bridge zid>/@ros2_lv/MP/<ns>§diagnostics_agg/diagnostic_msgs§msg§DiagnosticArray/<qos>`.
Both carry the DDS CDR sample with its encapsulation header.

rmw_zenoh's publisher GID is the XXH3-128 hash of the publisher's liveliness token, and each sample's
attachment carries its publisher's GID: so a sample on the un-namespaced `/diagnostics`, which every
diagnostic_updater node publishes on, tells whose node (whose namespace) sent it.
"""

from __future__ import annotations

import re
import struct
from typing import NamedTuple

import xxhash

from overseer.sources.topic_names import AGGREGATED, RAW

DIAGNOSTIC_ARRAY_TYPE = "diagnostic_msgs::msg::dds_::DiagnosticArray_"
# REP-2011 hash of diagnostic_msgs/msg/DiagnosticArray (Jazzy); tests/sources/zenoh/test_zenoh_keys.py
# recomputes it.
DIAGNOSTIC_ARRAY_HASH = "RIHS01_5a8a36efb05fb25070fa0fb3810290c0e6cd4862b54a8fb975a1ee8dc55a333e"
LIVELINESS_SPACE = "@ros2_lv"
PUBLISHER_ENTITY = "MP"
BRIDGE_TYPE = "diagnostic_msgs/msg/DiagnosticArray"
_BRIDGE_SLASH = "\u00a7"  # the bridge writes `/` as `§` inside a token's chunks
RMW_ZENOH = "rmw_zenoh"
BRIDGE = "bridge"
KEY_FORMATS = (RMW_ZENOH, BRIDGE)
_KINDS = (AGGREGATED, RAW)
# ROS 2 name tokens: what a namespace may hold (rmw_zenoh and the bridge only carry valid ROS names).
_TOKEN = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")
# The number of chunks of a publisher token, from the admin space to the QoS.
_TOKEN_CHUNKS = 13


class RejectedKey(ValueError):
    """A key that is not a robot's diagnostics; its message is the reason counted in the metrics."""


class DiagnosticsKey(NamedTuple):
    """A diagnostics topic heard over Zenoh: whose, which kind, in which key format, with which hash."""

    namespace: str  # '' when the topic has no namespace
    kind: str  # diagnostics_agg or diagnostics
    key_format: str  # rmw_zenoh or bridge
    type_hash: str  # '' for the bridge, which sends none

    @property
    def topic(self) -> str:
        """The ROS topic without its leading slash, e.g. `site_a/robot7/diagnostics_agg`."""
        return f"{self.namespace}/{self.kind}" if self.namespace else self.kind


def data_subscriptions(domain: int, formats: tuple[str, ...]) -> list[str]:
    """The key expressions to subscribe to for every robot's diagnostics in the given formats."""
    keys = []
    for kind in _KINDS:
        if RMW_ZENOH in formats:
            keys.append(f"{domain}/**/{kind}/*/*")  # any type and hash: a wrong one is counted
        if BRIDGE in formats:
            keys.append(f"**/{kind}")
    return keys


def unnamespaced_subscriptions(domain: int, formats: tuple[str, ...]) -> list[str]:
    """The key expressions of the diagnostics topics without a namespace, which any robot may publish on."""
    keys = []
    for kind in _KINDS:
        if RMW_ZENOH in formats:
            keys.append(f"{domain}/{kind}/*/*")
        if BRIDGE in formats:
            keys.append(kind)
    return keys


def followed_subscription(topic: DiagnosticsKey, domain: int) -> str:
    """The key expression of one namespaced diagnostics topic, any type hash, in its key format."""
    if topic.key_format == BRIDGE:
        return bridge_key(topic.namespace, topic.kind)
    return data_key(domain, topic.namespace, topic.kind, topic.type_hash)


def liveliness_subscription(domain: int) -> str:
    """The key expression of the liveliness tokens of every diagnostics publisher on `domain`.

    It names the message type in its chunk and has no wildcard inside a chunk (`$*`): a router matches
    every token it holds against the expression when the exporter subscribes with its history, and an
    expression such as `$*diagnostics$*` made a router of 10,000 robots' 20,000 tokens spend 14 s of a
    core on it, against 3.5 s (dropping samples meanwhile).
    """
    return f"{LIVELINESS_SPACE}/{domain}/*/*/*/{PUBLISHER_ENTITY}/*/*/*/*/{DIAGNOSTIC_ARRAY_TYPE}/*/*"


def bridge_liveliness_subscription() -> str:
    """The key expression of the tokens zenoh-bridge-ros2dds declares for routed diagnostics publishers."""
    return f"@/*/{LIVELINESS_SPACE}/{PUBLISHER_ENTITY}/*/{BRIDGE_TYPE.replace('/', _BRIDGE_SLASH)}/*"


def parse_data_key(key: str, domain: int) -> DiagnosticsKey:
    """Recognise a data key of either format; RejectedKey (with the reason to count) otherwise."""
    chunks = key.split("/")
    if chunks[-1] in _KINDS:  # the bridge: <ns>/diagnostics_agg
        return DiagnosticsKey(_namespace(chunks[:-1]), chunks[-1], BRIDGE, "")
    if len(chunks) < 4 or chunks[0] != str(domain) or chunks[-3] not in _KINDS:
        raise RejectedKey("unrecognised_key")
    if chunks[-2] != DIAGNOSTIC_ARRAY_TYPE:
        raise RejectedKey("unexpected_type")
    return DiagnosticsKey(_namespace(chunks[1:-3]), chunks[-3], RMW_ZENOH, chunks[-1])


class PublisherToken(NamedTuple):
    """An rmw_zenoh diagnostics publisher, as its liveliness token announces it."""

    topic: DiagnosticsKey
    node_namespace: str  # '/robot_a', or '/' for none
    node_name: str
    gid: bytes


def parse_publisher(key: str, domain: int) -> PublisherToken | None:
    """The diagnostics publisher an rmw_zenoh liveliness token announces; None for any other token."""
    topic = parse_publisher_token(key, domain)
    if topic is None:
        return None
    chunks = key.split("/")
    return PublisherToken(topic, chunks[7].replace("%", "/"), chunks[8], publisher_gid(key))


def publisher_gid(token: str) -> bytes:
    """rmw_zenoh's GID of the entity a liveliness token announces: XXH3-128 of the token, low half first."""
    return xxhash.xxh3_128(token.encode()).intdigest().to_bytes(16, "little")


ATTACHMENT_SIZE = 33  # rmw_zenoh (Jazzy): sequence number, source timestamp (int64), GID (length 16, bytes)
_GID_SIZE = 16
_NAMED_GID = b"\x0asource_gid"  # the earlier attachment named its fields


def attachment_gid(attachment: bytes | None) -> bytes | None:
    """The publisher GID an rmw_zenoh sample's attachment carries, or None (none, or not understood)."""
    if attachment is None:
        return None
    if len(attachment) == ATTACHMENT_SIZE and attachment[16] == _GID_SIZE:
        return attachment[17:]
    at = attachment.rfind(_NAMED_GID)
    if at < 0:
        return None
    rest = attachment[at + len(_NAMED_GID) :]
    if len(rest) == _GID_SIZE + 1 and rest[0] == _GID_SIZE:
        return rest[1:]
    return rest if len(rest) == _GID_SIZE else None


_NAMED_SEQUENCE = b"\x0fsequence_number"
_NAMED_TIMESTAMP = b"\x10source_timestamp"
_SEQUENCE = struct.Struct("<q")


def attachment_fields(attachment: bytes | None) -> tuple[bytes | None, int | None]:
    """The publisher GID and the sequence number of an rmw_zenoh sample, each None when not understood."""
    gid = attachment_gid(attachment)
    if gid is None or attachment is None:
        return None, None
    if len(attachment) == ATTACHMENT_SIZE:
        return gid, int(_SEQUENCE.unpack_from(attachment)[0])
    at = attachment.find(_NAMED_SEQUENCE) + len(_NAMED_SEQUENCE)
    after = at + _SEQUENCE.size
    if at < len(_NAMED_SEQUENCE) or attachment[after : after + len(_NAMED_TIMESTAMP)] != _NAMED_TIMESTAMP:
        return gid, None  # no number, or not followed by the field that comes next
    return gid, int(_SEQUENCE.unpack_from(attachment, at)[0])


def parse_publisher_token(key: str, domain: int) -> DiagnosticsKey | None:
    """The diagnostics topic whose publisher a liveliness token announces; None for any other token."""
    chunks = key.split("/")
    if (
        len(chunks) != _TOKEN_CHUNKS
        or chunks[0] != LIVELINESS_SPACE
        or chunks[1] != str(domain)
        or chunks[5] != PUBLISHER_ENTITY
        or chunks[10] != DIAGNOSTIC_ARRAY_TYPE
    ):
        return None
    topic = chunks[9].replace("%", "/").strip("/").split("/")
    if topic[-1] not in _KINDS:
        return None
    try:
        return DiagnosticsKey(_namespace(topic[:-1]), topic[-1], RMW_ZENOH, chunks[11])
    except RejectedKey:
        return None


def parse_bridge_token(key: str) -> DiagnosticsKey | None:
    """The diagnostics topic a bridge's publisher token announces; None for any other token."""
    chunks = key.split("/")
    if (
        len(chunks) != 7
        or chunks[0] != "@"
        or chunks[2] != LIVELINESS_SPACE
        or chunks[3] != PUBLISHER_ENTITY
        or chunks[5].replace(_BRIDGE_SLASH, "/") != BRIDGE_TYPE
    ):
        return None
    topic = chunks[4].replace(_BRIDGE_SLASH, "/").split("/")
    if topic[-1] not in _KINDS:
        return None
    try:
        return DiagnosticsKey(_namespace(topic[:-1]), topic[-1], BRIDGE, "")
    except RejectedKey:
        return None


def bridge_publisher_token(zid: str, namespace: str, kind: str) -> str:
    """The token zenoh-bridge-ros2dds declares while it routes `/<namespace>/<kind>` (reliable, depth 10)."""
    topic = bridge_key(namespace, kind).replace("/", _BRIDGE_SLASH)
    typ = BRIDGE_TYPE.replace("/", _BRIDGE_SLASH)
    return f"@/{zid}/{LIVELINESS_SPACE}/{PUBLISHER_ENTITY}/{topic}/{typ}/:1:0:0,10"


def data_key(domain: int, namespace: str, kind: str, type_hash: str = DIAGNOSTIC_ARRAY_HASH) -> str:
    """The key rmw_zenoh publishes topic `/<namespace>/<kind>` on."""
    topic = f"{namespace}/{kind}" if namespace else kind
    return f"{domain}/{topic}/{DIAGNOSTIC_ARRAY_TYPE}/{type_hash}"


def bridge_key(namespace: str, kind: str) -> str:
    """The key zenoh-bridge-ros2dds routes DDS topic `/<namespace>/<kind>` on."""
    return f"{namespace}/{kind}" if namespace else kind


def publisher_token(
    domain: int,
    zid: str,
    entity_id: int,
    namespace: str,
    node: str,
    kind: str,
    type_hash: str,
    topic_namespace: str | None = None,
) -> str:
    """The liveliness token rmw_zenoh declares for a publisher of `/<namespace>/<kind>` (default QoS).

    The topic's namespace is the node's, unless `topic_namespace` says otherwise: diagnostic_updater
    publishes on the absolute `/diagnostics` (`topic_namespace=""`) from a node in any namespace.
    """
    ns = _mangled("/" + namespace)
    in_topic = namespace if topic_namespace is None else topic_namespace
    topic = _mangled(f"/{in_topic}/{kind}" if in_topic else f"/{kind}")
    qos = "::,:,:,:,,"  # every policy at rmw_zenoh's default
    return (
        f"{LIVELINESS_SPACE}/{domain}/{zid}/0/{entity_id}/{PUBLISHER_ENTITY}/%/{ns}/{node}/{topic}/"
        f"{DIAGNOSTIC_ARRAY_TYPE}/{type_hash}/{qos}"
    )


def node_token(domain: int, zid: str, namespace: str, node: str) -> str:
    """The liveliness token rmw_zenoh declares for a node."""
    return f"{LIVELINESS_SPACE}/{domain}/{zid}/0/0/NN/%/{_mangled('/' + namespace)}/{node}"


def _mangled(name: str) -> str:
    return name.replace("/", "%")


def _namespace(tokens: list[str]) -> str:
    if not all(_TOKEN.fullmatch(token) for token in tokens):
        raise RejectedKey("invalid_namespace")
    return "/".join(tokens)
