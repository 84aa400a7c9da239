"""The DDS domain joined as a ROS 2 node joins it, with no ROS installation.

ROS 2's environment decides the domain and the reach of discovery (``ROS_DOMAIN_ID``,
``ROS_AUTOMATIC_DISCOVERY_RANGE``, ``ROS_STATIC_PEERS``, the older ``ROS_LOCALHOST_ONLY=1``),
turned into a Cyclone DDS configuration as ``rmw_cyclonedds_cpp`` turns it, so the monitor is
found by, and finds, the robot's nodes and no others. Topics are named as ROS 2 names them on
DDS (``/robot1/joint_states`` is ``rt/robot1/joint_states``) with the QoS of ROS 2's profiles:
a ROS tool sees the monitor as one more node's topics.
"""

from __future__ import annotations

import os
import re
import time
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass
from typing import Any, NamedTuple
from xml.sax.saxutils import quoteattr

from cyclonedds._clayer import ddspy_take, ddspy_write, ddspy_write_ts
from cyclonedds.builtin import BuiltinDataReader, BuiltinTopicDcpsPublication
from cyclonedds.core import DDSException, DDSStatus, InstanceState, Policy, Qos, ReadCondition, SampleState, ViewState, WaitSet
from cyclonedds.domain import Domain, DomainParticipant
from cyclonedds.internal import dds_infinity
from cyclonedds.pub import DataWriter
from cyclonedds.sub import DataReader
from cyclonedds.topic import Topic
from cyclonedds.util import duration

from neural_asm.ros2.messages import STORE, idl_type

RANGES = ("SUBNET", "LOCALHOST", "OFF", "SYSTEM_DEFAULT")
MAX_DOMAIN_ID = 232  # the largest id whose RTPS ports fit in UDP (ROS 2's documented limit)
TOPIC_PREFIX = "rt"  # ROS 2's prefix of a topic's DDS name
TAKE_AT_ONCE = 1 << 16  # more than any reader's history holds

# ROS 2's XCDR1 encoding and no disposal when a writer goes, as rmw_cyclonedds_cpp sets them.
_COMMON = (Policy.DataRepresentation(use_cdrv0_representation=True), Policy.WriterDataLifecycle(autodispose=False))
# rclcpp's SensorDataQoS: a subscription that matches reliable and best-effort publishers alike
# and keeps only the newest samples.
SENSOR_DATA = Qos(Policy.Reliability.BestEffort, Policy.Durability.Volatile, Policy.History.KeepLast(5), *_COMMON)
# The monitor's subscriptions: matched as SENSOR_DATA is (history is no part of matching), but
# holding a second of a 1 kHz stream, so that no sample is dropped while the node is busy judging.
MONITOR = Qos(Policy.Reliability.BestEffort, Policy.Durability.Volatile, Policy.History.KeepLast(1000), *_COMMON)
# rclcpp's default QoS (the ``ros2 topic echo`` default): nothing lost while the reader keeps up.
DEFAULT = Qos(Policy.Reliability.Reliable(max_blocking_time=dds_infinity), Policy.Durability.Volatile,
              Policy.History.KeepLast(10), *_COMMON)

_TOKEN = r"[A-Za-z_][A-Za-z0-9_]*"
_RELATIVE = re.compile(rf"{_TOKEN}(/{_TOKEN})*")
_ABSOLUTE = re.compile(rf"(/{_TOKEN})+")


@dataclass(frozen=True)
class Discovery:
    """Where the participant looks for others: ROS 2's automatic discovery range and static peers."""

    range: str = "SUBNET"
    static_peers: tuple[str, ...] = ()

    @classmethod
    def from_env(cls, env: Mapping[str, str] = os.environ) -> Discovery:
        """As rcl reads it: ``ROS_LOCALHOST_ONLY=1`` wins (peers ignored); otherwise
        ``ROS_AUTOMATIC_DISCOVERY_RANGE`` (unset: SUBNET) and ``ROS_STATIC_PEERS`` (``;``-separated)."""
        if env.get("ROS_LOCALHOST_ONLY") == "1":
            return cls("LOCALHOST")
        found = env.get("ROS_AUTOMATIC_DISCOVERY_RANGE") or "SUBNET"
        if found not in RANGES:
            raise ValueError(f"ROS_AUTOMATIC_DISCOVERY_RANGE={found!r}: expected one of {', '.join(RANGES)}")
        return cls(found, tuple(p for p in env.get("ROS_STATIC_PEERS", "").split(";") if p))

    def config(self) -> str:
        """The Cyclone DDS configuration of this range, as ``rmw_cyclonedds_cpp`` writes it, except
        that LOCALHOST also keeps to the loopback interface (as Humble's ``ROS_LOCALHOST_ONLY``
        did): its locators and its traffic stay on 127.0.0.1. Empty for SYSTEM_DEFAULT."""
        if self.range == "SYSTEM_DEFAULT":
            return ""
        general = "<AllowMulticast>false</AllowMulticast>" if self.range in ("LOCALHOST", "OFF") else ""
        if self.range == "LOCALHOST":
            general = '<Interfaces><NetworkInterface address="127.0.0.1"/></Interfaces>' + general
        if self.range == "OFF":  # a tag no other process has: no participant is ever discovered
            discovery = f"<ParticipantIndex>none</ParticipantIndex><Tag>ros_discovery_off_{os.getpid()}</Tag>"
        else:
            peers = ("127.0.0.1",) * (self.range == "LOCALHOST") + self.static_peers
            discovery = ("<ParticipantIndex>auto</ParticipantIndex><MaxAutoParticipantIndex>32</MaxAutoParticipantIndex>"
                         + (f"<Peers>{''.join(f'<Peer address={quoteattr(p)}/>' for p in peers)}</Peers>" if peers else ""))
        return f"<CycloneDDS><Domain><General>{general}</General><Discovery>{discovery}</Discovery></Domain></CycloneDDS>"


def domain_id_from_env(env: Mapping[str, str] = os.environ) -> int:
    """``ROS_DOMAIN_ID`` (unset or empty: 0)."""
    text = env.get("ROS_DOMAIN_ID") or "0"
    if not text.isdigit() or int(text) > MAX_DOMAIN_ID:
        raise ValueError(f"ROS_DOMAIN_ID={text!r}: expected a whole number from 0 to {MAX_DOMAIN_ID}")
    return int(text)


def resolve(name: str, namespace: str = "") -> str:
    """A ROS 2 topic name resolved as a node in ``namespace`` resolves it: a relative name is
    put under the namespace (``joint_states`` in ``/robot1`` is ``/robot1/joint_states``), an
    absolute one (``/diagnostics``) is kept."""
    if namespace not in ("", "/") and not _ABSOLUTE.fullmatch(namespace):
        raise ValueError(f"namespace {namespace!r} is not a ROS 2 namespace (like /robot1)")
    if _ABSOLUTE.fullmatch(name):
        return name
    if not _RELATIVE.fullmatch(name):
        raise ValueError(f"topic {name!r} is not a ROS 2 topic name (like joint_states or /robot1/joint_states)")
    return f"{namespace.rstrip('/')}/{name}"


_DOMAINS: dict[int, tuple[str, Domain]] = {}  # one configuration per domain id and process, as Cyclone allows


def _domain(domain_id: int, discovery: Discovery, env: Mapping[str, str]) -> None:
    """The process's domain ``domain_id`` with this discovery; the user's ``CYCLONEDDS_URI`` is
    read after it (and so can refine it), as ``rmw_cyclonedds_cpp`` reads it."""
    config = ",".join(part for part in (discovery.config(), env.get("CYCLONEDDS_URI", "")) if part)
    if domain_id in _DOMAINS:
        if _DOMAINS[domain_id][0] != config:
            raise ValueError(f"DDS domain {domain_id} is already joined with another discovery configuration")
        return
    _DOMAINS[domain_id] = (config, Domain(domain_id, config or None))


def _wait_until(waitset: WaitSet, done: Callable[[], bool], timeout_s: float) -> bool:
    """Wake at each status change of the waitset's entities until ``done()`` or ``timeout_s``."""
    deadline = time.monotonic() + timeout_s
    while not done():
        left = deadline - time.monotonic()
        if left <= 0:
            return False
        waitset.wait(duration(seconds=left))
    return True


def _topic(participant: DomainParticipant, topic: str, msgtype: str) -> Topic:
    """The DDS topic of a resolved ROS 2 topic name and message type."""
    return Topic(participant, TOPIC_PREFIX + topic, idl_type(msgtype))


def _status_waitset(participant: DomainParticipant, entity: DataReader | DataWriter, status: int) -> WaitSet:
    """A waitset woken by ``status`` changes of ``entity`` (its matches)."""
    entity.set_status_mask(status)
    waitset = WaitSet(participant)
    waitset.attach(entity)
    return waitset


class Received(NamedTuple):
    message: Any  # the ``rosbags`` message, as the bag reader decodes it
    sent_ns: int  # when the publisher wrote it (its clock, nanoseconds since the Unix epoch)


class Reader:
    """A subscription to one topic of one message type."""

    def __init__(self, participant: DomainParticipant, topic: str, msgtype: str, qos: Qos):
        self.topic, self.msgtype = topic, msgtype
        self._reader = DataReader(participant, _topic(participant, topic, msgtype), qos=qos)
        self.condition = ReadCondition(self._reader, SampleState.NotRead | ViewState.Any | InstanceState.Any)
        self._matched = _status_waitset(participant, self._reader, DDSStatus.SubscriptionMatched)

    def take(self) -> list[Received]:
        """Every message waiting, oldest first, in one take (a publisher's leaving notice is no
        message). Their CDR bytes are decoded by ``rosbags`` as the bag reader decodes a bag's: the
        DDS binding's own Python decoder (``DataReader.take``) costs several times as much."""
        taken = ddspy_take(self._reader._ref, self.condition.mask, TAKE_AT_ONCE)
        if isinstance(taken, int):
            raise DDSException(taken, f"taking the messages of {self.topic}")
        return [Received(STORE.deserialize_cdr(data, self.msgtype), info.source_timestamp)
                for data, info in taken if info.valid_data]

    def lost(self) -> int:
        """Messages DDS knows were sent to this subscription but never reached it (best effort
        drops them when the receiving socket overflows); a full history replaces its oldest
        sample unannounced, which only a publisher's count can tell."""
        return int(self._reader.get_sample_lost_status().total_count)

    def publishers(self) -> int:
        """How many publishers this subscription is matched with."""
        return int(self._reader.get_subscription_matched_status().current_count)

    def wait_for_publishers(self, count: int, timeout_s: float) -> bool:
        """Whether ``count`` publishers matched within ``timeout_s``: a message from a publisher
        this subscription has not discovered yet is dropped."""
        return _wait_until(self._matched, lambda: self.publishers() >= count, timeout_s)


class Writer:
    """A publisher of one topic and message type."""

    def __init__(self, participant: DomainParticipant, topic: str, msgtype: str, qos: Qos):
        self.topic, self.msgtype = topic, msgtype
        self._writer = DataWriter(participant, _topic(participant, topic, msgtype), qos=qos)
        self._matched = _status_waitset(participant, self._writer, DDSStatus.PublicationMatched)

    def write(self, message: Any, sent_ns: int | None = None) -> None:
        """Publish a ``rosbags`` message of this writer's type, stamped as sent now or at
        ``sent_ns`` (a logged message played again keeps its log time)."""
        if message.__msgtype__ != self.msgtype:
            raise TypeError(f"{self.topic} carries {self.msgtype}, not {message.__msgtype__}")
        # ``rosbags``' CDR bytes (those of the DDS type, tests/ros2 checks), padded as ``DataWriter.write`` pads
        cdr = bytes(STORE.serialize_cdr(message, self.msgtype))
        cdr += bytes(-len(cdr) % 4)
        ret = ddspy_write(self._writer._ref, cdr) if sent_ns is None else ddspy_write_ts(self._writer._ref, cdr, sent_ns)
        if ret < 0:
            raise DDSException(ret, f"writing a message of {self.topic}")

    def subscribers(self) -> int:
        """How many subscriptions this publisher is matched with."""
        return int(self._writer.get_publication_matched_status().current_count)

    def wait_for_subscribers(self, count: int, timeout_s: float) -> bool:
        """Whether ``count`` subscriptions matched within ``timeout_s``: a volatile topic keeps
        nothing for a subscriber that has not been discovered yet."""
        return _wait_until(self._matched, lambda: self.subscribers() >= count, timeout_s)


class Bus:
    """One participant in the DDS domain (a ROS 2 node's share of it) under a namespace, its
    readers and writers, and one wait for any of its readers to hold messages."""

    def __init__(self, namespace: str = "", env: Mapping[str, str] = os.environ):
        resolve("x", namespace)  # a bad namespace fails here, before joining
        domain_id = domain_id_from_env(env)
        _domain(domain_id, Discovery.from_env(env), env)
        self._share(namespace, domain_id, DomainParticipant(domain_id))

    def _share(self, namespace: str, domain_id: int, participant: DomainParticipant) -> None:
        self.namespace, self.domain_id, self._participant = namespace, domain_id, participant
        self._waitset = WaitSet(participant)
        self._publications: BuiltinDataReader | None = None

    def under(self, namespace: str) -> Bus:
        """This participant under another namespace, with a wait of its own: the nodes of many
        robots in one process share one participant (discovery on loopback admits 32 a host)."""
        resolve("x", namespace)
        other = Bus.__new__(Bus)
        other._share(namespace, self.domain_id, self._participant)
        return other

    def reader(self, name: str, msgtype: str, qos: Qos = SENSOR_DATA) -> Reader:
        """A subscription to ``name`` resolved in the bus's namespace (sensor-data QoS unless told)."""
        reader = Reader(self._participant, resolve(name, self.namespace), msgtype, qos)
        self._waitset.attach(reader.condition)
        return reader

    def writer(self, name: str, msgtype: str, qos: Qos = DEFAULT) -> Writer:
        """A publisher of ``name`` resolved in the bus's namespace (ROS 2's default QoS unless told)."""
        return Writer(self._participant, resolve(name, self.namespace), msgtype, qos)

    def publications(self) -> list[tuple[str, str]]:
        """The ROS 2 topics and DDS type names of the writers discovered since the last call (this
        participant's own and non-ROS topics left out): how a publisher of a mapped topic with
        another type is found, which DDS would otherwise just never match."""
        if self._publications is None:
            self._publications = BuiltinDataReader(self._participant, BuiltinTopicDcpsPublication)
            self._waitset.attach(ReadCondition(self._publications, SampleState.NotRead | ViewState.Any
                                               | InstanceState.Any))
        mine = self._participant.guid
        return [(p.topic_name.removeprefix(TOPIC_PREFIX), p.type_name) for p in self._publications.take(N=TAKE_AT_ONCE)
                if p.sample_info.valid_data and p.participant_key != mine and p.topic_name.startswith(TOPIC_PREFIX + "/")]

    def wait(self, timeout_s: float) -> bool:
        """Block until a reader holds a message not yet taken, or ``timeout_s``; whether one does."""
        return self._waitset.wait(duration(seconds=max(timeout_s, 0.0))) > 0

    def wait_for(self, readers: Iterable[Reader]) -> Callable[[float], bool]:
        """A wait of its own for any of ``readers`` (of this participant, under any namespace) to
        hold a message not yet taken: how one thread serves the nodes of many robots."""
        waitset = WaitSet(self._participant)
        for reader in readers:
            waitset.attach(reader.condition)
        return lambda timeout_s: waitset.wait(duration(seconds=max(timeout_s, 0.0))) > 0
