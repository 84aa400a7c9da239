"""The ROS 2 messages of the node, generated from ``rosbags``' definitions, are ROS 2's on the
wire: each serialises to the bytes ``rosbags``' CDR serialiser writes for the same values
(encapsulation header included), under the type name a ROS 2 node uses."""

from __future__ import annotations

from dataclasses import fields
from typing import Any, Callable

import numpy as np
import pytest

pytest.importorskip("cyclonedds")

from rosbags.interfaces import Nodetype  # noqa: E402
from rosbags.typesys import Stores, get_typestore  # noqa: E402

from neural_asm.ros2 import messages as m  # noqa: E402

TIME = {"sec": 1_714_000_123, "nanosec": 999_999_999}
HEADER = {"stamp": TIME, "frame_id": "panda_link0"}
VECTOR3 = {"x": 1.5, "y": -0.25, "z": 9.81}
WRENCH = {"force": VECTOR3, "torque": {"x": 0.0, "y": 3e-9, "z": -120.0}}
KEY_VALUE = {"key": "energy", "value": "3.0417"}
STATUS = {"level": 2, "name": "nasm: fault monitor", "message": "fault: joint 4 isolated", "hardware_id": "robot1",
          "values": [KEY_VALUE, {"key": "threshold", "value": "1.9"}, {"key": "isolated_joint", "value": "4"},
                     {"key": "skill", "value": "pick_and_place"}]}
VALUES: dict[str, dict[str, Any]] = {
    m.TIME: TIME,
    m.HEADER: HEADER,
    # names of odd lengths before float arrays: the 8-byte alignment of the doubles is exercised
    m.JOINT_STATE: {"header": HEADER, "name": ["panda_joint1", "j2", "panda_joint_three"],
                    "position": [0.1, -1.25, 3.0], "velocity": [0.0, 1e-3, -2.5], "effort": []},
    m.WRENCH_STAMPED: {"header": {"stamp": {"sec": 0, "nanosec": 1}, "frame_id": ""}, "wrench": WRENCH},
    "geometry_msgs/msg/Wrench": WRENCH,
    "geometry_msgs/msg/Vector3": VECTOR3,
    m.POINT_STAMPED: {"header": HEADER, "point": VECTOR3},
    "geometry_msgs/msg/Point": VECTOR3,
    m.STRING: {"data": "kitting/pick"},
    m.BOOL: {"data": True},
    m.FLOAT64: {"data": -12345.678},
    m.KEY_VALUE: KEY_VALUE,
    m.DIAGNOSTIC_STATUS: STATUS,
    m.DIAGNOSTIC_ARRAY: {"header": HEADER, "status": [STATUS, {**STATUS, "level": 0, "message": "ok", "values": []}]},
}
NAMES = {  # as rmw_cyclonedds_cpp names them
    m.JOINT_STATE: "sensor_msgs::msg::dds_::JointState_",
    m.WRENCH_STAMPED: "geometry_msgs::msg::dds_::WrenchStamped_",
    "geometry_msgs/msg/Wrench": "geometry_msgs::msg::dds_::Wrench_",
    "geometry_msgs/msg/Vector3": "geometry_msgs::msg::dds_::Vector3_",
    m.POINT_STAMPED: "geometry_msgs::msg::dds_::PointStamped_",
    "geometry_msgs/msg/Point": "geometry_msgs::msg::dds_::Point_",
    m.STRING: "std_msgs::msg::dds_::String_",
    m.BOOL: "std_msgs::msg::dds_::Bool_",
    m.FLOAT64: "std_msgs::msg::dds_::Float64_",
    m.HEADER: "std_msgs::msg::dds_::Header_",
    m.TIME: "builtin_interfaces::msg::dds_::Time_",
    m.DIAGNOSTIC_ARRAY: "diagnostic_msgs::msg::dds_::DiagnosticArray_",
    m.DIAGNOSTIC_STATUS: "diagnostic_msgs::msg::dds_::DiagnosticStatus_",
    m.KEY_VALUE: "diagnostic_msgs::msg::dds_::KeyValue_",
}


def build(make: Callable[[str], Any], msgtype: str, values: dict[str, Any], numbers: Callable[[list], Any]) -> Any:
    """A message of ``msgtype`` from plain values: nested dicts become nested messages, lists of
    numbers go through ``numbers`` (numpy arrays for ``rosbags``, lists for the DDS types)."""
    kwargs = {}
    for name, (kind, detail) in m.STORE.fielddefs[msgtype][1]:
        value = values[name]
        if kind == Nodetype.NAME:
            value = build(make, detail, value, numbers)
        elif kind == Nodetype.SEQUENCE and detail[0][0] == Nodetype.NAME:
            value = [build(make, detail[0][1], v, numbers) for v in value]
        elif kind == Nodetype.SEQUENCE and detail[0][1][0] != "string":
            value = numbers(value)
        kwargs[name] = value
    return make(msgtype)(**kwargs)


def ros(msgtype: str) -> Any:
    return build(m.STORE.types.__getitem__, msgtype, VALUES[msgtype], lambda v: np.array(v, dtype=np.float64))


def dds(msgtype: str) -> Any:
    return build(m.idl_type, msgtype, VALUES[msgtype], list)


def test_every_type_the_node_uses_is_checked():
    assert set(m.MESSAGES) <= set(VALUES) == set(NAMES)


@pytest.mark.parametrize("msgtype", sorted(VALUES))
def test_the_bytes_are_ros2s(msgtype):
    expected = bytes(m.STORE.serialize_cdr(ros(msgtype), msgtype))
    assert expected[:4] == b"\x00\x01\x00\x00"  # CDR, little endian: what ROS 2 sends
    assert dds(msgtype).serialize() == expected


@pytest.mark.parametrize("msgtype", sorted(VALUES))
def test_the_type_is_named_as_ros2_names_it_with_the_stores_fields(msgtype):
    idl = m.idl_type(msgtype)
    assert idl.__idl_typename__ == NAMES[msgtype]
    assert m.ros_typename(NAMES[msgtype]) == msgtype
    assert [f.name for f in fields(idl)] == [name for name, _ in m.STORE.fielddefs[msgtype][1]]


def test_humble_and_jazzy_define_these_messages_alike():
    humble, jazzy = get_typestore(Stores.ROS2_HUMBLE), get_typestore(Stores.ROS2_JAZZY)
    assert all(humble.fielddefs[t] == jazzy.fielddefs[t] for t in VALUES)


@pytest.mark.parametrize("msgtype", m.MESSAGES)
def test_the_dds_type_reads_ros2s_bytes_as_the_same_values(msgtype):
    """The node writes ``rosbags``' bytes under the DDS type's name: the type reads them whole."""
    assert m.idl_type(msgtype).deserialize(bytes(m.STORE.serialize_cdr(ros(msgtype), msgtype))) == dds(msgtype)


def test_a_joint_state_comes_back_as_the_bag_reader_decodes_it():
    back = m.STORE.deserialize_cdr(dds(m.JOINT_STATE).serialize(), m.JOINT_STATE)
    assert isinstance(back.position, np.ndarray) and back.position.tolist() == [0.1, -1.25, 3.0]
    assert back.name == ["panda_joint1", "j2", "panda_joint_three"] and back.header.stamp.nanosec == 999_999_999


def test_a_type_outside_the_store_is_named():
    with pytest.raises(KeyError, match="not_a_pkg/msg/Nothing"):
        m.idl_type("not_a_pkg/msg/Nothing")
