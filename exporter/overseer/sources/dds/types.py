"""ROS 2 diagnostic_msgs types as DDS sees them, with the exact type names ROS 2 writers register.

Fast DDS (Jazzy's default RMW) matches readers and writers by type name only, so these names are the
contract with the robots. `level` is an octet, as rosidl maps ROS `byte`; a uint8 type object crashes
Cyclone C 0.10 readers. The fields exist for type matching and the simulator's type object: payloads
are read and written raw and go through `overseer.codec.cdr`.
"""

from dataclasses import dataclass

from cyclonedds.idl import IdlStruct, types

DIAGNOSTIC_ARRAY_TYPE_NAME = "diagnostic_msgs::msg::dds_::DiagnosticArray_"


@dataclass
class Time(IdlStruct, typename="builtin_interfaces.msg.dds_.Time_"):
    """builtin_interfaces/msg/Time."""

    sec: types.int32
    nanosec: types.uint32


@dataclass
class Header(IdlStruct, typename="std_msgs.msg.dds_.Header_"):
    """std_msgs/msg/Header."""

    stamp: Time
    frame_id: str


@dataclass
class KeyValue(IdlStruct, typename="diagnostic_msgs.msg.dds_.KeyValue_"):
    """diagnostic_msgs/msg/KeyValue."""

    key: str
    value: str


@dataclass
class DiagnosticStatus(IdlStruct, typename="diagnostic_msgs.msg.dds_.DiagnosticStatus_"):
    """diagnostic_msgs/msg/DiagnosticStatus."""

    level: types.byte
    name: str
    message: str
    hardware_id: str
    values: types.sequence[KeyValue]


@dataclass
class DiagnosticArray(IdlStruct, typename="diagnostic_msgs.msg.dds_.DiagnosticArray_"):
    """diagnostic_msgs/msg/DiagnosticArray."""

    header: Header
    status: types.sequence[DiagnosticStatus]


@dataclass
class Gid(IdlStruct, typename="rmw_dds_common.msg.dds_.Gid_"):
    """rmw_dds_common/msg/Gid (Iron and later: 16 bytes)."""

    data: types.array[types.uint8, 16]


@dataclass
class NodeEntitiesInfo(IdlStruct, typename="rmw_dds_common.msg.dds_.NodeEntitiesInfo_"):
    """rmw_dds_common/msg/NodeEntitiesInfo."""

    node_namespace: types.bounded_str[256]
    node_name: types.bounded_str[256]
    reader_gid_seq: types.sequence[Gid]
    writer_gid_seq: types.sequence[Gid]


@dataclass
class ParticipantEntitiesInfo(IdlStruct, typename="rmw_dds_common.msg.dds_.ParticipantEntitiesInfo_"):
    """rmw_dds_common/msg/ParticipantEntitiesInfo: a process's nodes and their endpoints."""

    gid: Gid
    node_entities_info_seq: types.sequence[NodeEntitiesInfo]
