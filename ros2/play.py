"""A robot's ROS 2 bags played onto the bus at their own pace, as ``ros2 bag play`` plays them,
so the monitor node can be tried without a robot: the mapping's topics (and its marker and
label topics) under the namespace, each message at its log time from the first (``speed``
times faster), sent stamped with that log time, so the node reads the stamps a bag reader
reads.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from neural_asm.logs.bagfiles import BagRead, find_bags, read_messages
from neural_asm.logs.errors import LogError
from neural_asm.logs.mapping import Episodes, Mapping
from neural_asm.ros2 import messages as m
from neural_asm.ros2.bus import Bus, Writer
from neural_asm.ros2.node import topic_type


@dataclass(frozen=True)
class Pace:
    """How the bags are played: ``speed`` times their own pace, after waiting up to ``wait_s``
    for a subscriber of every mapped topic (a volatile topic keeps nothing for a late one)."""

    speed: float = 1.0
    wait_s: float = 30.0


def _writers(bus: Bus, mapping: Mapping) -> dict[str, Writer]:
    """A writer per topic the mapping reads, of the type the node reads it as."""
    assert isinstance(mapping.source, Episodes)
    topics = list(dict.fromkeys(c.topic for c in mapping.channels if c.topic))
    writers = {t: bus.writer(t.lstrip("/"), topic_type(t, [c.field or "" for c in mapping.channels if c.topic == t]))
               for t in topics}
    for t in (mapping.source.marker_topic, mapping.source.label_topic):
        if t:
            writers[t] = bus.writer(t.lstrip("/"), m.STRING)
    return writers


def play_bags(bus: Bus, source: Path, mapping: Mapping, pace: Pace = Pace(),
         said: Callable[[str], None] = print) -> int:
    """Play every bag of ``source`` onto ``bus``; the messages sent. A LogError when nothing
    subscribes, a bag is a ROS 1 bag, or a topic's type is not the one the mapping reads."""
    if not isinstance(mapping.source, Episodes):
        raise LogError(f"only ROS 2 bags can be played onto the bus, not a {mapping.kind} source")
    writers = _writers(bus, mapping)
    channel_topics = {c.topic for c in mapping.channels}
    for topic, writer in writers.items():
        if topic in channel_topics and not writer.wait_for_subscribers(1, pace.wait_s):
            raise LogError(f"nothing subscribed to {writer.topic} within {pace.wait_s:g} s: is nasm ros2 running "
                           f"in ROS domain {bus.domain_id}?")
    sent = 0
    for bag in find_bags(source):
        if any(f.suffix == ".bag" for f in bag.files):
            raise LogError(f"bag {bag.name} is a ROS 1 bag: only ROS 2 bags (CDR messages) can be played")
        read, start = BagRead(), None
        for topic, log_ns, raw, _ in read_messages(bag, set(writers), read):
            writer = writers[topic]
            if read.types[topic] != writer.msgtype:
                raise LogError(f"bag {bag.name}: {topic} holds {read.types[topic]}, the mapping reads {writer.msgtype}")
            start = start or (time.monotonic(), log_ns)
            time.sleep(max(0.0, start[0] + (log_ns - start[1]) / 1e9 / pace.speed - time.monotonic()))
            writer.write(m.STORE.deserialize_cdr(raw, writer.msgtype), sent_ns=log_ns)
            sent += 1
        if read.damage:
            said(read.damage)
    return sent
