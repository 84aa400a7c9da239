"""Bags on disk and their messages, read with ``rosbags`` (pure Python, no ROS installation):
ROS 2 bags in MCAP or sqlite3 storage (one ``.mcap``/``.db3`` file, a rosbag2 folder with its
``metadata.yaml``, or a folder of either) and ROS 1 ``.bag`` files. Messages are decoded from
the definitions stored in the bag, or, for a bag that stores none (ROS 2 Humble's sqlite3
bags), from ``rosbags``' own type store of the ROS 2 LTS messages.

An MCAP file whose recorder died has no index or footer; ``rosbags`` refuses it, so it is read
front to back with ``mcap``'s non-seeking reader and every message before the cut is used. Any
other damage stops the bag's reading where it is found: ``BagRead.damage`` says where and
what was read before. What was read is checked against what the bag declares (its index,
``metadata.yaml``): missing messages are listed in ``BagRead.missing``.
"""

from __future__ import annotations

import functools
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Iterator

import yaml
from mcap.reader import NonSeekingReader
from rosbags.interfaces import MessageDefinitionFormat
from rosbags.rosbag1 import Reader as Ros1Reader
from rosbags.rosbag2 import Reader as Ros2Reader
from rosbags.typesys import Stores, get_types_from_idl, get_types_from_msg, get_typestore
from rosbags.typesys.store import Typestore

from neural_asm.logs.errors import LogError
from neural_asm.logs.formats import BAG_METADATA as METADATA
from neural_asm.logs.formats import BAG_SUFFIXES as SUFFIXES

STORAGES = {"mcap": ".mcap", "sqlite3": ".db3"}
DEFAULT_STORE = Stores.ROS2_HUMBLE  # messages of bags that store no definitions (Humble's sqlite3)
DEFAULT_STORE_ROS1 = Stores.ROS1_NOETIC

Decode = Callable[[bytes], Any]


@dataclass(frozen=True)
class Bag:
    name: str
    files: list[Path]
    declared: dict[str, int] = field(default_factory=dict)  # messages per topic in metadata.yaml


@dataclass
class BagRead:
    """What reading a bag found besides its messages."""

    types: dict[str, str] = field(default_factory=dict)  # every topic of the bag -> its type
    counts: Counter = field(default_factory=Counter)  # messages read per mapped topic
    indexed: bool = False  # the file being read listed its topics when opened
    damage: str | None = None  # why reading stopped early, and what was kept
    missing: list[str] = field(default_factory=list)  # declared messages that were not read


def _bag_folder(folder: Path) -> Bag:
    try:
        info = yaml.safe_load((folder / METADATA).read_text())["rosbag2_bagfile_information"]
        storage, paths = info.get("storage_identifier"), info["relative_file_paths"]
        counts = {t["topic_metadata"]["name"]: int(t["message_count"])
                  for t in info.get("topics_with_message_count") or [] if "message_count" in t}
    except (OSError, yaml.YAMLError, KeyError, TypeError, ValueError) as exc:
        raise LogError(f"{folder / METADATA} is not a rosbag2 metadata file: {exc}") from None
    if storage not in STORAGES:
        raise LogError(f"bag {folder} uses {storage!r} storage; this reads mcap and sqlite3 bags")
    if info.get("compression_mode") == "FILE" or any(not str(p).endswith(STORAGES[storage]) for p in paths):
        raise LogError(f"bag {folder}: its files are compressed whole ({paths}); decompress them "
                       "(`ros2 bag convert`) or record with per-message compression")
    files = [folder / p for p in paths]
    missing = [str(p) for p in files if not p.exists()]
    if missing:
        raise LogError(f"bag {folder}: {METADATA} names files that are not there: {missing}")
    return Bag(folder.name, files, counts)


def find_bags(source: Path) -> list[Bag]:
    """The bags of a source, in name order: a file, a rosbag2 folder, or a folder of them."""
    if source.is_file():
        if source.suffix not in SUFFIXES:
            raise LogError(f"{source} is not a bag file (.mcap or .db3 for ROS 2, .bag for ROS 1)")
        return [Bag(source.stem, [source])]
    if (source / METADATA).exists():
        return [_bag_folder(source)]
    bags = [Bag(p.stem, [p]) if p.is_file() else _bag_folder(p) for p in sorted(source.iterdir())
            if (p.is_file() and p.suffix in SUFFIXES) or (p / METADATA).exists()]
    if not bags:
        raise LogError(f"{source} holds no bag (.mcap, .db3 or .bag files, or folders with {METADATA})")
    return bags


@functools.lru_cache(maxsize=64)
def _schema_store(name: str, encoding: str, text: str, ros1: bool = False) -> Typestore:
    """A type store for one stored definition; without one (empty text), the ROS LTS store."""
    if not text.strip():
        return get_typestore(DEFAULT_STORE_ROS1 if ros1 else DEFAULT_STORE)
    store = get_typestore(Stores.EMPTY)
    store.register(get_types_from_idl(text) if encoding == "ros2idl" else get_types_from_msg(text, name))
    return store


def _scan_mcap(path: Path, topics: set[str], read: BagRead) -> Iterator[tuple[str, int, bytes, Decode]]:
    """Every record of an MCAP file front to back: what precedes a cut is kept."""
    decoders: dict[int, Decode] = {}
    with open(path, "rb") as f:
        for schema, channel, message in NonSeekingReader(f).iter_messages(log_time_order=False):
            read.types[channel.topic] = schema.name if schema is not None else "(no schema)"
            if channel.topic not in topics:
                continue
            if channel.id not in decoders:
                if channel.message_encoding != "cdr" or schema is None:
                    raise LogError(f"{path}: topic {channel.topic} is {channel.message_encoding!r} encoded, not ROS 2 CDR")
                store = _schema_store(schema.name, schema.encoding, schema.data.decode())
                decoders[channel.id] = functools.partial(store.deserialize_cdr, typename=schema.name)
            read.counts[channel.topic] += 1
            yield channel.topic, message.log_time, message.data, decoders[channel.id]


Reader = Ros1Reader | Ros2Reader


def _open(path: Path) -> Reader:
    reader: Reader = Ros1Reader(path) if path.suffix == ".bag" else Ros2Reader(path)
    reader.open()
    return reader


def _decoder(c: Any, ros1: bool) -> Decode:
    """Decode a connection's messages with its own definition, or the LTS types if it stores none."""
    fmt, text = c.msgdef.format, c.msgdef.data
    store = _schema_store(c.msgtype, "ros2idl" if fmt == MessageDefinitionFormat.IDL else "ros2msg",
                          "" if fmt == MessageDefinitionFormat.NONE else text, ros1)
    return functools.partial(store.deserialize_ros1 if ros1 else store.deserialize_cdr, typename=c.msgtype)


def _read_indexed(reader: Reader, topics: set[str], read: BagRead,
                  declared: Counter) -> Iterator[tuple[str, int, bytes, Decode]]:
    read.types.update({c.topic: c.msgtype for c in reader.connections})
    read.indexed = True
    connections = [c for c in reader.connections if c.topic in topics]
    for c in connections:
        declared[c.topic] += c.msgcount
    ros1 = isinstance(reader, Ros1Reader)
    known = {c.id: (c.topic, _decoder(c, ros1)) for c in connections}
    counts = read.counts
    if connections:  # rosbags reads every topic when given none
        for c, t, raw in reader.messages(connections=connections):
            topic, decode = known[c.id]
            counts[topic] += 1
            yield topic, t, raw, decode


def read_messages(bag: Bag, topics: set[str], read: BagRead) -> Iterator[tuple[str, int, bytes, Decode]]:
    """(topic, log time ns, raw message, its decoder) of the mapped ``topics``, in each file's
    order; damage ends the reading with ``read.damage`` set, never an exception."""
    declared: Counter = Counter()
    for path in bag.files:
        before = sum(read.counts.values())
        try:
            try:
                reader = _open(path)
            except Exception as exc:  # noqa: BLE001  (rosbags refuses an MCAP without footer: scan it)
                if path.suffix != ".mcap":
                    raise
                opened, read.indexed = None, False
                messages = _scan_mcap(path, topics, read)
                declared_here = f"{type(exc).__name__}: {exc}"
            else:
                opened, declared_here = reader, ""
                messages = _read_indexed(reader, topics, read, declared)
            try:
                yield from messages
            finally:
                if opened is not None:
                    opened.close()
            if declared_here:
                read.damage = (f"{path} has no index ({declared_here}); read front to back, "
                               f"{sum(read.counts.values()) - before} messages of the mapped topics were kept")
        except LogError:
            raise
        except Exception as exc:  # noqa: BLE001  (whatever a damaged file makes its reader raise)
            kept = sum(read.counts.values()) - before
            read.damage = (f"{path} is truncated or damaged after {kept} messages of the mapped topics "
                           f"({type(exc).__name__}: {exc}); the messages before that are used")
            return  # later files of a broken recording are not trusted either
    if read.damage is None:
        for source, counts in (("its index", declared), (METADATA, Counter(bag.declared))):
            read.missing += [f"{source} declares {n} messages on {t}, {read.counts[t]} were read"
                             for t, n in sorted(counts.items()) if t in topics and read.counts[t] < n]
