"""Logged episodes played onto the bus at their own pace, as ``ros2 bag play`` plays a bag, so the
monitor node can be tried without a robot (``nasm replay --ros2``).

Whatever ``nasm replay`` reads through a mapping (ROS 2 and ROS 1 bags, LeRobot datasets, a lab's
tables) arrives here as episodes on the model's clock. Each step is published as the node's
mapping reads it: every channel on its topic, in the message type the node reads that topic as
(``node.topic_type``), at its field and joint name or index, in the recorded units (before the
channel's ``scale``), stamped (header and source time) at its time, and sent at that pace (``speed`` times faster):
at each step and between steps as often as the mapping's ``max_gap_s`` needs, so the node's
resampler finds each step's values again.
Episodes are cut as the node's mapping cuts them: a message on its marker or label topic (the
episode's skill) before each, and a pause longer than its ``gap_s`` between them.
"""

from __future__ import annotations

import copy
import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from rosbags.interfaces import Nodetype

from neural_asm.client.source import StreamedEpisode
from neural_asm.logs.errors import LogError
from neural_asm.logs.fields import NS
from neural_asm.logs.mapping import Episodes, Mapping
from neural_asm.logs.resample import Group
from neural_asm.logs.rosbag import topic_groups
from neural_asm.ros2 import messages as m
from neural_asm.ros2.bus import Bus, Writer
from neural_asm.ros2.node import topic_type

T = m.STORE.types
# ROS 2 primitive types as the numpy types of ``rosbags``' arrays of them
NUMPY: dict[str, Any] = {"bool": np.bool_, "byte": np.uint8, "char": np.uint8, "int8": np.int8, "uint8": np.uint8,
                         "int16": np.int16, "uint16": np.uint16, "int32": np.int32, "uint32": np.uint32,
                         "int64": np.int64, "uint64": np.uint64, "float32": np.float32, "float64": np.float64}


@dataclass(frozen=True)
class Pace:
    """How the episodes are played: ``speed`` times their own pace, after waiting up to ``wait_s``
    for a subscriber of every topic (a volatile topic keeps nothing for a late one)."""

    speed: float = 1.0
    wait_s: float = 30.0


def _zero(node: tuple[Any, Any]) -> Any:
    """The zero value of one field of a ``rosbags`` definition (empty sequences, zero arrays)."""
    kind, detail = node
    if kind == Nodetype.BASE:
        return {"string": "", "bool": False}.get(detail[0], 0.0 if detail[0].startswith("float") else 0)
    if kind == Nodetype.NAME:
        return zero_message(detail)
    element, size = detail
    length = size if kind == Nodetype.ARRAY else 0
    if element[0] == Nodetype.BASE and element[1][0] != "string":
        return np.zeros(length, NUMPY[element[1][0]])
    return [_zero(element) for _ in range(length)]


def zero_message(msgtype: str) -> Any:
    """A ``rosbags`` message of ``msgtype`` with every field zero or empty."""
    return T[msgtype](**{name: _zero(node) for name, node in m.STORE.fielddefs[msgtype][1]})


def _parent(message: Any, field: str) -> tuple[Any, str]:
    """The object holding a dotted field's last part, and that part."""
    *path, last = field.split(".")
    for part in path:
        message = getattr(message, part)
    return message, last


class Composer:
    """One topic's message from its channels' values: the inverse of the node's ``extractor``."""

    def __init__(self, group: Group, msgtype: str) -> None:
        self.group, self.msgtype = group, msgtype
        self.template = zero_message(msgtype)
        keys = list(dict.fromkeys(c.key for c in group.channels if c.key is not None))
        for ch in group.channels:
            if ch.key is None and ch.index is None:
                continue
            parent, last = _parent(self.template, ch.field or "")
            known = len(getattr(parent, last))
            length = len(keys) if ch.key is not None else max(known, (ch.index or 0) + 1)
            setattr(parent, last, np.zeros(length, getattr(parent, last).dtype))
            if ch.key is not None:
                parent.name = keys  # JointState's name[]: an element by name
        self.places = [(ch.field or "", keys.index(ch.key) if ch.key is not None else ch.index) for ch in group.channels]
        self.scales = np.array([ch.scale for ch in group.channels])

    def message(self, values: np.ndarray, stamp_ns: int) -> Any:
        """The message of the channels' ``values`` (model units), stamped ``stamp_ns`` if it has a header."""
        message = copy.deepcopy(self.template)
        for (field, at), value in zip(self.places, values / self.scales):
            parent, last = _parent(message, field)
            if at is not None:
                getattr(parent, last)[at] = value
            else:
                kind = type(getattr(parent, last))
                setattr(parent, last, bool(value) if kind is bool else int(round(value)) if kind is int else float(value))
        if hasattr(message, "header"):
            message.header.stamp = T[m.TIME](sec=stamp_ns // NS, nanosec=stamp_ns % NS)
        return message


def between(rows: np.ndarray, per_step: int, linear: np.ndarray) -> np.ndarray:
    """(T, D) steps as ``per_step`` samples a step (linear channels interpolated, the others held),
    and one more holding the last: the sample after a step is what tells a resampler it is complete."""
    f = np.arange((len(rows) - 1) * per_step + 2)
    k, frac = np.minimum(f // per_step, len(rows) - 1), (f % per_step / per_step)[:, None]
    before, after = rows[k], rows[np.minimum(k + 1, len(rows) - 1)]
    return np.where(linear, before + frac * (after - before), before)


def _check(mapping: Mapping, episodes: Sequence[StreamedEpisode]) -> Episodes:
    """The node's split, once every episode is one the node can read as its mapping says."""
    if not isinstance(mapping.source, Episodes):
        raise LogError(f"the node reads topics: the mapping given to play onto the bus reads a {mapping.kind} "
                       "source, not a ROS bag's topics")
    timing, names = mapping.timing, set(mapping.channel_names)
    for ep in episodes:
        missing, extra = sorted(names - set(ep.channel_names)), sorted(set(ep.channel_names) - names)
        if missing or extra:
            raise LogError(f"episode {ep.number} has channels the node's mapping does not (missing {missing}, "
                           f"extra {extra})")
        if not math.isclose(ep.period_s, timing.period_s, rel_tol=1e-6):
            raise LogError(f"episode {ep.number} has a step every {ep.period_s:g} s, the node's mapping every "
                           f"{timing.period_s:g} s")
        steps = len(ep.observations)
        if steps > timing.steps or (steps < timing.steps and mapping.source.split == "file"):
            raise LogError(f"episode {ep.number} has {steps} steps and the node's mapping cuts its episodes after "
                           f"{timing.steps}" + ("" if steps > timing.steps else " (give it split = 'gap' or 'marker')"))
    return mapping.source


def play_episodes(bus: Bus, episodes: Sequence[StreamedEpisode], mapping: Mapping, pace: Pace = Pace(),
                  said: Callable[[str], None] = print) -> int:
    """Play ``episodes`` onto ``bus`` as the node reading ``mapping`` reads them; the messages sent.
    A LogError when an episode is not one the node reads or nothing subscribes."""
    split = _check(mapping, episodes)
    groups = topic_groups(mapping)
    topics = []
    for group in groups:
        topic = group.source.removeprefix("topic ")
        msgtype = topic_type(topic, [c.field or "" for c in group.channels])
        topics.append((bus.writer(topic.lstrip("/"), msgtype), Composer(group, msgtype)))
    control = [bus.writer(t.lstrip("/"), m.STRING) for t in dict.fromkeys((split.marker_topic, split.label_topic)) if t]
    for writer in [w for w, _ in topics] + control:
        if not writer.wait_for_subscribers(1, pace.wait_s):
            raise LogError(f"nothing subscribed to {writer.topic} within {pace.wait_s:g} s: is nasm ros2 running "
                           f"with this mapping in ROS domain {bus.domain_id}?")
    period_ns = round(mapping.timing.period_s * NS)
    per_step = math.ceil(mapping.timing.period_s / mapping.timing.gap_limit_s - 1e-9)  # no silence past max_gap_s
    gap_ns = round(split.gap_s * NS) if split.split == "gap" and split.gap_s else 0  # a silence that ends an episode
    linear = np.array([c.interpolation == "linear" for c in mapping.channels])
    start_ns, start_s, t_ns, sent = time.time_ns(), time.monotonic(), 0, 0
    for ep in episodes:
        rows = between(ep.observations[:, [ep.channel_names.index(c.name) for c in mapping.channels]], per_step, linear)
        offsets = np.round(np.arange(len(rows)) * period_ns / per_step).astype(np.int64)
        for k, (row, offset) in enumerate(zip(rows, offsets.tolist())):
            time.sleep(max(0.0, start_s + (t_ns + offset) / NS / pace.speed - time.monotonic()))
            stamp = start_ns + t_ns + offset
            if k == 0:
                for writer in control:
                    writer.write(T[m.STRING](data=ep.skill), sent_ns=stamp)
            for (writer, composer), group in zip(topics, groups):
                writer.write(composer.message(row[list(group.columns)], stamp), sent_ns=stamp)
            sent += len(topics) + (len(control) if k == 0 else 0)
        t_ns += int(offsets[-1]) + period_ns + gap_ns
        said(f"played episode {ep.number} ({ep.skill}, {len(ep.observations)} steps)")
    return sent
