"""The log formats, in one registry: each is a ``Reader``, its mapping section (the ``[source]``
table, told apart by ``kind``), how a source of it is recognised on disk and how it is read.

A new format is one module (its section and its reader) and one ``register`` call; the mapping
schema, the choice of reader and every help text naming the formats follow from the registry
(docs/robot_logs.md, "Adding a format"). The three formats shipped are declared here, each
reading with its own module, imported when it reads: naming the formats costs no reader's
dependencies.
"""

from __future__ import annotations

import importlib
from pathlib import Path
from typing import TYPE_CHECKING, Iterator, Protocol

from neural_asm.logs.mapping import Dataset, Episodes, Section, Table

if TYPE_CHECKING:
    from neural_asm.logs.mapping import Mapping
    from neural_asm.logs.recorded import Recorded

BAG_SUFFIXES = (".mcap", ".db3", ".bag")
BAG_METADATA = "metadata.yaml"  # rosbag2's description of a bag folder
LEROBOT_INFO = Path("meta/info.json")
TABLE_SUFFIXES = {".csv": "csv", ".tsv": "tsv", ".txt": "whitespace", ".dat": "whitespace", ".parquet": "parquet"}


class Reader(Protocol):
    """One log format."""

    kind: str  # the mapping's source.kind, and the section's
    named: str  # a source of it, in help texts and messages: "a LeRobot dataset"
    section: type[Section]  # its [source] section: kind: Literal[kind], address, its settings

    def recognises(self, source: Path) -> bool:
        """Whether ``source`` looks like this format, from names on disk alone (nothing is read)."""
        ...

    def read(self, source: Path, mapping: Mapping, skip_bad: bool) -> Iterator[Recorded | str]:
        """Each episode of ``source`` resampled to the mapping's clock (its ``number`` in the
        source, in reading order); strings are warnings (with ``skip_bad``, a skipped episode)."""
        ...


_READERS: dict[str, Reader] = {}


def register(reader: Reader) -> Reader:
    """Add a format (or replace the one of its kind); its section's kind must be its own."""
    if reader.section.model_fields["kind"].default != reader.kind:
        raise ValueError(f"the {reader.kind} reader's section has kind {reader.section.model_fields['kind'].default!r}")
    _READERS[reader.kind] = reader
    return reader


def readers() -> tuple[Reader, ...]:
    """The registered formats, in the order they were registered."""
    return tuple(_READERS.values())


def reader(kind: str) -> Reader:
    if kind not in _READERS:
        raise KeyError(f"no reader of {kind!r} sources; registered: {', '.join(_READERS)}")
    return _READERS[kind]


def recognised(source: Path) -> Reader | None:
    """The first format that recognises ``source``, if any."""
    return next((r for r in _READERS.values() if r.recognises(source)), None)


def described() -> str:
    """The registered formats in one phrase, for help texts: "a ROS bag source, ... or a lab's tables"."""
    names = [r.named for r in _READERS.values()]
    return names[0] if len(names) == 1 else f"{', '.join(names[:-1])} or {names[-1]}"


class _BuiltIn:
    """A format of this package: its reader module (``neural_asm.logs.<module>``, imported when a
    source is read, so that naming the formats loads neither pyarrow nor rosbags) reads it."""

    module: str

    def read(self, source: Path, mapping: Mapping, skip_bad: bool) -> Iterator[Recorded | str]:
        reader = importlib.import_module(f"neural_asm.logs.{self.module}")
        return reader.read_episodes(source, mapping, skip_bad)  # type: ignore[no-any-return]


class BagReader(_BuiltIn):
    kind = module = "rosbag"
    named = "a ROS bag source (.mcap, .db3, .bag, a rosbag2 folder or a folder of them)"
    section = Episodes

    def recognises(self, source: Path) -> bool:
        if source.is_file():
            return source.suffix in BAG_SUFFIXES
        return source.is_dir() and ((source / BAG_METADATA).exists() or any(
            (p.is_file() and p.suffix in BAG_SUFFIXES) or (p / BAG_METADATA).exists() for p in source.iterdir()))


class LeRobotReader(_BuiltIn):
    kind = module = "lerobot"
    named = "a LeRobot dataset"
    section = Dataset

    def recognises(self, source: Path) -> bool:
        return (source / LEROBOT_INFO).is_file()


class TableReader(_BuiltIn):
    kind = "table"
    module = "tables"
    named = "a lab's tables (CSV, TSV, text, Parquet: a file or a folder)"
    section = Table

    def recognises(self, source: Path) -> bool:
        if source.is_file():
            return source.suffix.lower() in TABLE_SUFFIXES
        return source.is_dir() and any(p.suffix.lower() in TABLE_SUFFIXES for p in source.rglob("*"))


for _builtin in (BagReader(), LeRobotReader(), TableReader()):
    register(_builtin)
