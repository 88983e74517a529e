"""ROS 2's graph as every DDS rmw publishes it: rmw_dds_common/msg/ParticipantEntitiesInfo, in CDR.

Each participant of a ROS 2 process publishes, on the DDS topic `ros_discovery_info`, its nodes with their
namespaces and names and the GIDs (DDS GUIDs) of each node's readers and writers. A DDS sample's writer GUID
then tells which node published it. Decoding is strict and bounded, as the diagnostics codec's: a hostile
sample costs at most its own size and ends in `DecodeError`.
"""

from __future__ import annotations

import struct
from typing import NamedTuple

from overseer.codec.cdr import ENCAPSULATION_CDR_LE, byte_order, read_string
from overseer.codec.errors import DecodeError

TOPIC = "ros_discovery_info"
TYPE_NAME = "rmw_dds_common::msg::dds_::ParticipantEntitiesInfo_"
GID_SIZE = 16  # rmw_dds_common/msg/Gid: uint8[16] since Iron
_MIN_NODE_BYTES = 16  # two empty strings (length and NUL), two empty sequences


class NodeEntities(NamedTuple):
    """One node of a participant: its namespace, its name and its writers' GIDs."""

    namespace: str
    name: str
    writers: tuple[bytes, ...]


class ParticipantEntities(NamedTuple):
    """One participant's nodes, as its latest `ros_discovery_info` sample lists them."""

    gid: bytes
    nodes: tuple[NodeEntities, ...]


def decode_participant_entities(payload: bytes) -> ParticipantEntities:
    """Decode a serialized ParticipantEntitiesInfo (with its 4-byte encapsulation header)."""
    u32 = byte_order(payload)
    end = len(payload)
    pos = 4
    if pos + GID_SIZE + 4 > end:
        raise DecodeError("payload too short for a participant")
    gid = payload[pos : pos + GID_SIZE]
    pos += GID_SIZE
    count, pos = _count(payload, pos, end, u32, _MIN_NODE_BYTES)
    nodes = []
    for _ in range(count):
        namespace, pos = read_string(payload, pos, end, u32)
        name, pos = read_string(payload, pos, end, u32)
        _, pos = _gids(payload, pos, end, u32)  # readers
        writers, pos = _gids(payload, pos, end, u32)
        nodes.append(NodeEntities(namespace, name, writers))
    return ParticipantEntities(gid, tuple(nodes))


def _count(payload: bytes, pos: int, end: int, u32: struct._UnpackFrom, smallest: int) -> tuple[int, int]:  # type: ignore[name-defined]
    pos = (pos + 3) & ~3
    if pos + 4 > end:
        raise DecodeError("payload ends before a sequence length")
    (count,) = u32(payload, pos)
    pos += 4
    if count * smallest > end - pos:
        raise DecodeError(f"sequence of {count} runs past the payload")
    return count, pos


def _gids(payload: bytes, pos: int, end: int, u32: struct._UnpackFrom) -> tuple[tuple[bytes, ...], int]:  # type: ignore[name-defined]
    count, pos = _count(payload, pos, end, u32, GID_SIZE)
    gids = tuple(payload[pos + GID_SIZE * i : pos + GID_SIZE * (i + 1)] for i in range(count))
    return gids, pos + GID_SIZE * count


def encode_participant_entities(participant: ParticipantEntities) -> bytes:
    """Serialize a ParticipantEntitiesInfo as XCDR1 little-endian with its header, as rmw writers do."""
    u32 = struct.Struct("<I").pack
    out = bytearray(ENCAPSULATION_CDR_LE)
    out += participant.gid

    def align() -> None:
        out.extend(b"\x00" * (-(len(out) - 4) & 3))

    def put_string(text: str) -> None:
        align()
        raw = text.encode("utf-8")
        out.extend(u32(len(raw) + 1) + raw + b"\x00")

    def put_gids(gids: tuple[bytes, ...]) -> None:
        align()
        out.extend(u32(len(gids)))
        for gid in gids:
            out.extend(gid)

    align()
    out.extend(u32(len(participant.nodes)))
    for node in participant.nodes:
        put_string(node.namespace)
        put_string(node.name)
        put_gids(())
        put_gids(node.writers)
    return bytes(out)
