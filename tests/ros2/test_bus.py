"""The bus joins DDS as ROS 2's environment says: the domain, the discovery range (loopback
really kept to 127.0.0.1), ROS 2's names; JointState messages from a publisher in another
process all arrive, in order, at a sensor-data subscription."""

from __future__ import annotations

import os
import random
import re
import subprocess
import sys
import time
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

pytest.importorskip("cyclonedds")

from neural_asm.ros2 import messages as m  # noqa: E402
from neural_asm.ros2.bus import DEFAULT, Bus, Discovery, domain_id_from_env, resolve  # noqa: E402

PUBLISHER = Path(__file__).with_name("joint_state_publisher.py")
DOMAIN = str(100 + random.randrange(100))  # one per run: parallel runs on one machine never mix
LOOPBACK = {"ROS_DOMAIN_ID": DOMAIN, "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST"}
COUNT = 40


def test_the_environment_chooses_the_discovery_range_as_rcl_does():
    assert Discovery.from_env({}) == Discovery("SUBNET")
    assert Discovery.from_env({"ROS_STATIC_PEERS": "10.0.0.2;robot.local"}).static_peers == ("10.0.0.2", "robot.local")
    assert Discovery.from_env({"ROS_LOCALHOST_ONLY": "1", "ROS_AUTOMATIC_DISCOVERY_RANGE": "SUBNET",
                               "ROS_STATIC_PEERS": "10.0.0.2"}) == Discovery("LOCALHOST")
    assert Discovery.from_env({"ROS_AUTOMATIC_DISCOVERY_RANGE": "OFF"}).range == "OFF"
    with pytest.raises(ValueError, match="ROS_AUTOMATIC_DISCOVERY_RANGE='lan'"):
        Discovery.from_env({"ROS_AUTOMATIC_DISCOVERY_RANGE": "lan"})


def test_localhost_keeps_to_the_loopback_interface_without_multicast():
    domain = ET.fromstring(Discovery("LOCALHOST").config()).find("Domain")
    assert [e.get("address") for e in domain.iter("NetworkInterface")] == ["127.0.0.1"]
    assert domain.findtext("General/AllowMulticast") == "false"
    assert [e.get("address") for e in domain.iter("Peer")] == ["127.0.0.1"]


def test_off_discovers_no_one_and_system_default_changes_nothing():
    domain = ET.fromstring(Discovery("OFF").config()).find("Domain")
    assert domain.findtext("Discovery/ParticipantIndex") == "none"
    assert domain.findtext("Discovery/Tag") == f"ros_discovery_off_{os.getpid()}"
    assert Discovery("SYSTEM_DEFAULT").config() == ""
    subnet = ET.fromstring(Discovery("SUBNET", ("10.0.0.2",)).config()).find("Domain")
    assert subnet.findtext("General/AllowMulticast") is None
    assert [e.get("address") for e in subnet.iter("Peer")] == ["10.0.0.2"]


def test_the_domain_id_is_ros_domain_id():
    assert domain_id_from_env({}) == 0 and domain_id_from_env({"ROS_DOMAIN_ID": "42"}) == 42
    for bad in ("-1", "7.5", "233", "robot"):
        with pytest.raises(ValueError, match="ROS_DOMAIN_ID"):
            domain_id_from_env({"ROS_DOMAIN_ID": bad})


def test_topic_names_resolve_as_in_a_ros2_node():
    assert resolve("joint_states", "/robot1") == "/robot1/joint_states"
    assert resolve("nasm/fault", "/") == "/nasm/fault" == resolve("nasm/fault")
    assert resolve("/diagnostics", "/robot1") == "/diagnostics"
    for name, namespace in (("joint states", ""), ("joint_states/", ""), ("//x", ""), ("2x", ""), ("x", "robot1")):
        with pytest.raises(ValueError, match="ROS 2"):
            resolve(name, namespace)


def test_a_writer_takes_only_its_type_and_a_domain_keeps_its_discovery():
    bus = Bus("/robot1", env=LOOPBACK)
    writer = bus.writer("nasm/fault", m.BOOL)
    assert writer.topic == "/robot1/nasm/fault"
    with pytest.raises(TypeError, match="std_msgs/msg/Bool, not std_msgs/msg/Float64"):
        writer.write(m.STORE.types[m.FLOAT64](data=1.0))
    with pytest.raises(ValueError, match=f"domain {DOMAIN} is already joined"):
        Bus(env={**LOOPBACK, "ROS_AUTOMATIC_DISCOVERY_RANGE": "OFF"})


def test_a_diagnostic_array_written_with_the_default_qos_is_read_back_whole():
    bus = Bus("/robot1", env=LOOPBACK)
    reader = bus.reader("/diagnostics", m.DIAGNOSTIC_ARRAY, qos=DEFAULT)
    writer = bus.writer("/diagnostics", m.DIAGNOSTIC_ARRAY)
    assert writer.wait_for_subscribers(1, timeout_s=30)
    T = m.STORE.types
    values = [T[m.KEY_VALUE](key="isolated_joint", value="4"), T[m.KEY_VALUE](key="energy", value="3.5")]
    status = T[m.DIAGNOSTIC_STATUS](level=T[m.DIAGNOSTIC_STATUS].ERROR, name="nasm", message="fault",
                                    hardware_id="robot1", values=values)
    header = T[m.HEADER](stamp=T[m.TIME](sec=3, nanosec=0), frame_id="")
    writer.write(T[m.DIAGNOSTIC_ARRAY](header=header, status=[status]))
    assert bus.wait(timeout_s=30)
    (received,) = reader.take()
    assert received.message.status == [status] and received.message.header == header


def test_namespaces_sharing_one_participant_read_only_their_own_topics_and_wake_their_own_wait():
    bus = Bus(env=LOOPBACK)
    robots = [bus.under(f"/robot{r}") for r in range(2)]
    readers = [robot.reader("fault", m.BOOL, qos=DEFAULT) for robot in robots]
    writer = bus.writer("/robot1/fault", m.BOOL)
    assert writer.wait_for_subscribers(1, timeout_s=30) and readers[0].publishers() == 0
    writer.write(m.STORE.types[m.BOOL](data=True))
    assert robots[1].wait(timeout_s=30) and not robots[0].wait(timeout_s=0)
    assert [r.message.data for r in readers[1].take()] == [True] and readers[0].take() == []
    assert [r.topic for r in readers] == ["/robot0/fault", "/robot1/fault"]


def selected_addresses(trace: str) -> set[str]:
    """The addresses of the interfaces a Cyclone DDS trace says the participant selected."""
    addresses = dict(re.findall(r"(\S+) udp/([\d.]+)\(", re.search(r" interfaces: (.*)", trace)[1]))
    return {addresses[name] for name in re.findall(r"(\S+) \(index", re.search(r"selected interfaces: (.*)", trace)[1])}


def test_joint_states_from_another_process_arrive_all_in_order_on_loopback(tmp_path):
    trace = tmp_path / "publisher.trace"
    tracing = f"<Tracing><Verbosity>config</Verbosity><OutputFile>{trace}</OutputFile></Tracing>"
    env = {**os.environ, **LOOPBACK, "CYCLONEDDS_URI": f"<CycloneDDS><Domain>{tracing}</Domain></CycloneDDS>"}
    child = subprocess.Popen([sys.executable, str(PUBLISHER), "/robot1", str(COUNT)], env=env, text=True,
                             stdin=subprocess.PIPE, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    try:
        bus = Bus(env=LOOPBACK)
        reader = bus.reader("/robot1/joint_states", m.JOINT_STATE)  # sensor-data QoS: best effort, keep last 5
        assert reader.wait_for_publishers(1, timeout_s=60), "the publisher was not discovered"
        child.stdin.write("go\n")
        child.stdin.flush()
        received = []
        deadline = time.monotonic() + 60
        while len(received) < COUNT and child.poll() is None and time.monotonic() < deadline:
            bus.wait(timeout_s=deadline - time.monotonic())
            received += reader.take()
    finally:
        child.kill()
        _, errors = child.communicate()
    assert [r.message.header.stamp.sec for r in received] == list(range(COUNT)), errors
    assert all(r.message.position.tolist() == [float(i)] * 7 for i, r in enumerate(received))
    assert received[0].message.name == [f"panda_joint{j}" for j in range(1, 8)]
    assert [r.sent_ns for r in received] == sorted(r.sent_ns for r in received)
    text = trace.read_text()
    assert selected_addresses(text) == {"127.0.0.1"}
    assert re.search(r"General/AllowMulticast/#text: false", text)
