"""ROS 2 bags in MCAP storage: one ``.mcap`` file, a rosbag2 folder (``metadata.yaml`` naming
its files), or a folder of either. Messages are decoded with ``mcap-ros2-support`` from the
message definitions stored in the bag, so no ROS installation is needed.

Files are read front to back (``NonSeekingReader``): a bag whose recorder died has no index or
footer, and everything before the cut is still used; the bag's last episode, which the cut
may have shortened, is then dropped with a warning instead of failing the whole source.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Iterator

import numpy as np
import yaml
import zstandard
from mcap.exceptions import McapError
from mcap.reader import NonSeekingReader
from mcap_ros2.decoder import DecoderFactory

from logs.errors import LogError
from logs.mapping import Channel, Episodes, Mapping
from logs.recorded import Recorded
from logs.resample import Stream, resample

METADATA = "metadata.yaml"  # rosbag2's description of a bag folder
NS = 1_000_000_000


@dataclass(frozen=True)
class Bag:
    name: str
    files: list[Path]


@dataclass
class BagMessages:
    """The decoded messages of the mapped topics, with (stamp ns, message) per topic."""

    by_topic: dict[str, list[tuple[int, Any]]]
    types: dict[str, str] = field(default_factory=dict)  # every topic of the bag -> its type
    damage: str | None = None  # why reading stopped early


def _bag_folder(folder: Path) -> Bag:
    try:
        info = yaml.safe_load((folder / METADATA).read_text())["rosbag2_bagfile_information"]
        storage, paths = info.get("storage_identifier"), info["relative_file_paths"]
    except (OSError, yaml.YAMLError, KeyError, TypeError) as exc:
        raise LogError(f"{folder / METADATA} is not a rosbag2 metadata file: {exc}") from None
    if storage != "mcap":
        raise LogError(f"bag {folder} uses {storage!r} storage; only MCAP bags are read "
                       "(`ros2 bag convert` or record with `-s mcap`)")
    files = [folder / p for p in paths]
    missing = [str(p) for p in files if not p.exists()]
    if missing:
        raise LogError(f"bag {folder}: {METADATA} names files that are not there: {missing}")
    return Bag(folder.name, files)


def find_bags(source: Path) -> list[Bag]:
    """The bags of a source, in name order: a file, a rosbag2 folder, or a folder of them."""
    if source.is_file():
        if source.suffix != ".mcap":
            raise LogError(f"{source} is not an .mcap file")
        return [Bag(source.stem, [source])]
    if (source / METADATA).exists():
        return [_bag_folder(source)]
    bags = [Bag(p.stem, [p]) if p.is_file() else _bag_folder(p)
            for p in sorted(source.iterdir()) if (p.is_file() and p.suffix == ".mcap") or (p / METADATA).exists()]
    if not bags:
        raise LogError(f"{source} holds no ROS 2 bag (.mcap files or folders with {METADATA})")
    return bags


def _stamp(message: Any, log_time: int) -> int:
    """header.stamp, or the log time for a message without a header (std_msgs/msg/Bool, String)."""
    stamp = getattr(getattr(message, "header", None), "stamp", None)
    return log_time if stamp is None else int(stamp.sec) * NS + int(stamp.nanosec)


def read_bag(bag: Bag, topics: set[str], stamp: str) -> BagMessages:
    """Decode the messages of ``topics``; a damaged file keeps what precedes the damage."""
    out = BagMessages({t: [] for t in topics})
    factory = DecoderFactory()
    decoders: dict[int, Callable[[bytes], Any]] = {}
    for path in bag.files:
        count = 0
        with open(path, "rb") as f:
            try:
                for schema, channel, message in NonSeekingReader(f).iter_messages(log_time_order=False):
                    out.types[channel.topic] = schema.name if schema is not None else "(no schema)"
                    count += 1
                    if channel.topic not in topics:
                        continue
                    if channel.id not in decoders:
                        decoder = factory.decoder_for(channel.message_encoding, schema)
                        if decoder is None:
                            raise LogError(f"{path}: topic {channel.topic} is {channel.message_encoding!r} "
                                           "encoded, not ROS 2 CDR with a ros2msg schema")
                        decoders[channel.id] = decoder
                    msg = decoders[channel.id](message.data)
                    t = message.log_time if stamp == "log" else _stamp(msg, message.log_time)
                    out.by_topic[channel.topic].append((t, msg))
            except (McapError, zstandard.ZstdError, struct.error, EOFError) as exc:
                out.damage = (f"{path} is truncated or damaged after {count} messages "
                              f"({type(exc).__name__}: {exc}); the messages before that are used")
                return out  # later files of a broken recording are not trusted either
    return out


def _fields(node: Any) -> list[str]:
    return list(getattr(node, "__slots__", []))


def _element(value: Any, parent: Any, ch: Channel, where: str) -> Any:
    """The scalar a channel names: the value itself, or an element by index or by name[]."""
    if isinstance(value, (str, bytes)):
        raise LogError(f"{where}: field {ch.field!r} is text ({value!r}), not a number")
    is_array = isinstance(value, (list, tuple, np.ndarray)) or hasattr(value, "__len__")
    if not is_array:
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


def channel_values(ch: Channel, messages: list[tuple[int, Any]], type_name: str) -> np.ndarray:
    """One float per message of the channel's field, or a LogError naming the field's problem."""
    where = f"topic {ch.topic} ({type_name}), channel {ch.name}"
    values = np.empty(len(messages))
    path = (ch.field or "").split(".")
    for n, (_, msg) in enumerate(messages):
        node, parent = msg, msg
        for part in path:
            if part not in _fields(node):
                raise LogError(f"{where}: no field {ch.field!r} ({part!r} is not among {_fields(node)})")
            parent, node = node, getattr(node, part)
        value = _element(node, parent, ch, where)
        if not isinstance(value, (bool, int, float, np.number)):
            raise LogError(f"{where}: field {ch.field!r} holds {type(value).__name__} values, not numbers")
        values[n] = float(value)
    return values


def _windows(msgs: BagMessages, mapping: Mapping, split: Episodes) -> list[tuple[int, int]]:
    """Episode windows [start, end) in ns."""
    channel_times = np.sort(np.concatenate(
        [[t for t, _ in msgs.by_topic[c.topic]] for c in mapping.channels]).astype(np.int64))  # type: ignore[index]
    if len(channel_times) == 0:
        return []
    last = int(channel_times[-1]) + 1
    if split.split == "file":
        return [(int(channel_times[0]), last)]
    if split.split == "marker":
        marks = sorted(t for t, _ in msgs.by_topic[split.marker_topic])  # type: ignore[index]
        if not marks:
            raise LogError(f"no message on the marker topic {split.marker_topic}")
        return list(zip(marks, marks[1:] + [max(last, marks[-1] + 1)]))
    cuts = np.flatnonzero(np.diff(channel_times) > (split.gap_s or 0) * NS)
    starts = np.concatenate([[0], cuts + 1])
    ends = np.concatenate([cuts, [len(channel_times) - 1]])
    return [(int(channel_times[a]), int(channel_times[b]) + 1) for a, b in zip(starts, ends)]


def _label(msgs: BagMessages, topic: str | None, lo: int, hi: int, default: str) -> str:
    names = [str(getattr(m, "data", "")) for t, m in msgs.by_topic.get(topic or "", []) if lo <= t < hi]
    return names[-1] if names else default


def read_episodes(source: Path, mapping: Mapping) -> Iterator[Recorded | str]:
    """Each episode of every bag of ``source``, resampled; strings are warnings to pass on."""
    split = mapping.split
    topics = {c.topic for c in mapping.channels} | {t for t in (split.marker_topic, split.label_topic) if t}
    for bag in find_bags(source):
        msgs = read_bag(bag, topics, split.stamp)  # type: ignore[arg-type]
        absent = sorted(t for t in topics if t not in msgs.types)
        if absent and msgs.damage is None:
            known = ", ".join(f"{t} ({ty})" for t, ty in sorted(msgs.types.items())) or "none"
            raise LogError(f"bag {bag.name} has no topic {', '.join(absent)}; its topics: {known}")
        if msgs.damage:
            yield msgs.damage
        windows = _windows(msgs, mapping, split)
        stamps = {t: np.array([s for s, _ in m], np.int64) for t, m in msgs.by_topic.items()}
        values = {ch.name: channel_values(ch, msgs.by_topic[ch.topic], msgs.types.get(ch.topic, "?"))  # type: ignore[index]
                  for ch in mapping.channels}
        for k, (lo, hi) in enumerate(windows):
            what = f"bag {bag.name}, episode {k}" + (f" (from {lo / NS:.3f} s)" if len(windows) > 1 else "")
            try:
                picked = {t: (s >= lo) & (s < hi) for t, s in stamps.items()}  # in bag order: stamps may go back
                streams = [Stream(ch, (stamps[ch.topic][picked[ch.topic]] - lo) / NS, values[ch.name][picked[ch.topic]])  # type: ignore[index]
                           for ch in mapping.channels]
                data = resample(streams, mapping.timing, what)
            except LogError as exc:
                if msgs.damage and k == len(windows) - 1:
                    yield f"dropped the last episode of the damaged bag {bag.name}: {exc}"
                    continue
                raise
            yield Recorded(data, _label(msgs, split.label_topic, lo, hi, bag.name), what, lo / NS)
