"""The numbers a mapping's channels name inside a decoded ROS message (a ``rosbags`` message
object): a dotted field path, then an element of an array by index or by the message's
``name[]`` (JointState), checked so that a wrong path is refused with what the message has."""

from __future__ import annotations

import dataclasses
from typing import Any, Callable

import numpy as np

from neural_asm.logs.errors import LogError
from neural_asm.logs.mapping import Channel

NS = 1_000_000_000


def field_names(node: Any) -> list[str]:
    """The fields of a message object (none for a plain value)."""
    if not dataclasses.is_dataclass(node):
        return []
    return [f.name for f in dataclasses.fields(node) if not f.name.startswith("__")]


def header_stamp(message: Any, log_time: int) -> int:
    """header.stamp in ns, or the log time for a message without a header (std_msgs/msg/Bool, String)."""
    stamp = getattr(getattr(message, "header", None), "stamp", None)
    return log_time if stamp is None else int(stamp.sec) * NS + int(stamp.nanosec)


def _element(value: Any, parent: Any, ch: Channel, where: str) -> Any:
    """The scalar a channel names: the value itself, or an element by index or by name[]."""
    if isinstance(value, (str, bytes)):
        raise LogError(f"{where}: field {ch.field!r} is text ({value!r}), not a number")
    if not isinstance(value, (list, tuple, np.ndarray)):
        if ch.index is not None or ch.key is not None:
            raise LogError(f"{where}: field {ch.field!r} is a single value; drop index/key")
        return value
    if ch.key is not None:
        names = list(getattr(parent, "name", None) or [])
        if ch.key not in names:
            raise LogError(f"{where}: no element named {ch.key!r} in name[] {names}")
        i = names.index(ch.key)
    elif ch.index is not None:
        i = ch.index
    else:
        raise LogError(f"{where}: field {ch.field!r} is an array of {len(value)}; give index or key")
    if i >= len(value):
        raise LogError(f"{where}: field {ch.field!r} has {len(value)} elements, index {i} is past its end")
    return value[i]


def channel_value(ch: Channel, message: Any, where: str) -> float:
    """One channel's number in one message, or a LogError naming the field's problem."""
    node = parent = message
    for part in (ch.field or "").split("."):
        if part not in field_names(node):
            raise LogError(f"{where}: no field {ch.field!r} ({part!r} is not among {field_names(node)})")
        parent, node = node, getattr(node, part)
    value = _element(node, parent, ch, where)
    if not isinstance(value, (bool, int, float, np.number)):
        raise LogError(f"{where}: field {ch.field!r} holds {type(value).__name__} values, not numbers")
    return float(value)


def extractor(channels: list[Channel], topic: str, type_name: str) -> Callable[[Any], np.ndarray]:
    """A function from a decoded message of ``topic`` to its channels' values, in order."""
    wheres = [f"topic {topic} ({type_name}), channel {ch.name}" for ch in channels]

    def values(message: Any) -> np.ndarray:
        return np.array([channel_value(ch, message, where) for ch, where in zip(channels, wheres)])

    return values
