"""The ROS 2 messages the monitor node reads and writes, as Cyclone DDS types.

Each type is generated from the definitions in ``rosbags``' type store of the ROS 2 LTS
messages, the store the bag reader decodes with (``logs.bagfiles.DEFAULT_STORE``), so no field
is typed in twice and the node's bytes on the wire are ROS 2's (``tests/ros2`` compares them
with ``rosbags``' CDR serialiser). Types are named as ``rmw_cyclonedds_cpp`` names them
(``sensor_msgs::msg::dds_::JointState_``), which is how a ROS 2 node matches a topic's type.

The types name and describe a topic on the bus (how DDS matches it with a ROS 2 node's); the
messages themselves are ``rosbags``' messages, written and read as those same bytes by
``rosbags``' CDR serialiser (``ros2.bus``), so the node hands the bag reader's code the messages
it already knows, without a second field-by-field copier.
"""

from __future__ import annotations

import functools
from typing import Any

from cyclonedds.idl import IdlStruct, make_idl_struct
from cyclonedds.idl import types as idl
from rosbags.interfaces import Nodetype
from rosbags.typesys import get_typestore

from neural_asm.logs.bagfiles import DEFAULT_STORE

STORE = get_typestore(DEFAULT_STORE)

JOINT_STATE = "sensor_msgs/msg/JointState"
WRENCH_STAMPED = "geometry_msgs/msg/WrenchStamped"
POINT_STAMPED = "geometry_msgs/msg/PointStamped"
STRING = "std_msgs/msg/String"
BOOL = "std_msgs/msg/Bool"
FLOAT64 = "std_msgs/msg/Float64"
DIAGNOSTIC_ARRAY = "diagnostic_msgs/msg/DiagnosticArray"
DIAGNOSTIC_STATUS = "diagnostic_msgs/msg/DiagnosticStatus"
KEY_VALUE = "diagnostic_msgs/msg/KeyValue"
HEADER = "std_msgs/msg/Header"
TIME = "builtin_interfaces/msg/Time"
MESSAGES = (JOINT_STATE, WRENCH_STAMPED, POINT_STAMPED, STRING, BOOL, FLOAT64, DIAGNOSTIC_ARRAY)  # what the node reads or writes

# ROS 2 primitive types as their IDL types (rosidl maps ``byte`` to octet, ``char`` to uint8).
PRIMITIVES: dict[str, Any] = {
    "bool": bool, "byte": idl.byte, "char": idl.uint8, "string": str,
    "int8": idl.int8, "uint8": idl.uint8, "int16": idl.int16, "uint16": idl.uint16,
    "int32": idl.int32, "uint32": idl.uint32, "int64": idl.int64, "uint64": idl.uint64,
    "float32": idl.float32, "float64": idl.float64,
}


def dds_typename(msgtype: str) -> str:
    """The DDS name of a ROS 2 message type: ``pkg/msg/Type`` -> ``pkg::msg::dds_::Type_``."""
    package, kind, name = msgtype.split("/")
    return f"{package}::{kind}::dds_::{name}_"


def ros_typename(typename: str) -> str:
    """The ROS 2 name of a DDS message type: ``pkg::msg::dds_::Type_`` -> ``pkg/msg/Type``."""
    package, kind, _, name = typename.split("::")
    return f"{package}/{kind}/{name.removesuffix('_')}"


def _field_type(node: tuple[Any, Any]) -> Any:
    """The IDL type of one field of a ``rosbags`` definition (a base type, a message, an array
    of fixed length or a sequence, bounded or not)."""
    kind, detail = node
    if kind == Nodetype.BASE:
        name, bound = detail
        if name not in PRIMITIVES:
            raise TypeError(f"ROS 2 primitive type {name!r} has no IDL type here")
        return idl.bounded_str[bound] if name == "string" and bound else PRIMITIVES[name]
    if kind == Nodetype.NAME:
        return idl_type(detail)
    element, size = detail
    if kind == Nodetype.ARRAY:
        return idl.array[_field_type(element), size]
    return idl.sequence[_field_type(element), size] if size else idl.sequence[_field_type(element)]


@functools.cache
def idl_type(msgtype: str) -> type[IdlStruct]:
    """The Cyclone DDS type of a ROS 2 message type of the store (its nested types too)."""
    if msgtype not in STORE.fielddefs:
        raise KeyError(f"{msgtype!r} is not a message type of the {DEFAULT_STORE.value} definitions")
    _, fields = STORE.fielddefs[msgtype]
    typename = dds_typename(msgtype)
    return make_idl_struct(typename.rsplit("::", 1)[1], typename, {name: _field_type(node) for name, node in fields})
