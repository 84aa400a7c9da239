"""The channel mapping file: which topic field, dataset feature element or table column becomes
which model channel, in which units, at which step period, and which channels are joints; and
the ``[source]`` section of the source's format, told apart by its ``kind`` (a discriminated
union of the registered formats' sections, ``logs.formats``): for bags, how a bag is cut into
episodes; for a lab's tables, which files, which column is time and where each episode's
skill, anomaly label and onset come from.

A mapping is TOML (``.toml``, read with tomllib) or YAML (``.yaml``/``.yml``); both hold the
same tables, checked here with one schema so that a typo is refused with the table, the
channel and the reason rather than turning into a silently wrong model. Mappings written
before ``[source]`` (an ``[episodes]`` or ``[table]`` section, or neither) read as before. See
``examples/panda_ros2.toml`` and docs/robot_logs.md.
"""

from __future__ import annotations

import functools
import tomllib
from pathlib import Path
from typing import Annotated, Any, ClassVar, Literal, Sequence, Union

import yaml
from pydantic import BaseModel, ConfigDict, Field, ValidationError, create_model, field_validator, model_validator

from neural_asm.logs.errors import LogError
from neural_asm.models.fault import JOINT_PREFIX

Address = Literal["topic", "feature", "column"]
TIME_UNITS: dict[str, float] = {"s": 1.0, "ms": 1e-3, "us": 1e-6, "ns": 1e-9}  # seconds per unit


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


class Timing(_Strict):
    """The model's clock: every episode is resampled to ``steps`` samples ``period_s`` apart."""

    period_s: float = Field(gt=0, description="the model's step period (s); 0.5 for the simulated Panda")
    steps: int = Field(ge=2, description="steps per episode; shorter episodes are refused")
    max_gap_s: float | None = Field(None, gt=0, description="longest silence of a stream inside an "
                                    "episode (default: period_s)")
    shorter: Literal["refuse", "hold"] = Field("refuse", description="an episode shorter than steps: refused, "
                                               "or (tables) padded by holding its last sample")

    @property
    def gap_limit_s(self) -> float:
        return self.period_s if self.max_gap_s is None else self.max_gap_s


class Section(_Strict):
    """The mapping's ``[source]`` section of one format: ``kind`` names the format; ``address`` is
    the field its channels are read by; ``pads`` whether ``timing.shorter = "hold"`` applies."""

    kind: str
    address: ClassVar[Address]
    pads: ClassVar[bool] = False

    def layout(self) -> list[str]:
        """What is read, in words (``nasm logs inspect``): the section's settings."""
        settings = self.model_dump(exclude_none=True, exclude={"kind"})
        return [f"{self.kind}: " + (", ".join(f"{k} = {v!r}" for k, v in settings.items()) or "as recorded")]


class Episodes(Section):
    """How a bag is cut into episodes and where their time stamps and skill names come from."""

    kind: Literal["rosbag"] = "rosbag"
    address: ClassVar[Address] = "topic"
    split: Literal["file", "marker", "gap"] = Field("file", description="file: one episode per bag; marker: "
                                                    "one per message on marker_topic; gap: a silence longer than gap_s")
    marker_topic: str | None = None
    gap_s: float | None = Field(None, gt=0)
    label_topic: str | None = Field(None, description="a std_msgs/msg/String topic whose data names the skill; "
                                    "a bag without it is read, its episodes named after the bag (with a warning)")
    label_tolerance_s: float = Field(0.5, ge=0, description="a label published up to this long before an "
                                     "episode's first sample still names it; live, the first step waits "
                                     "this long of the topics' time for a label")
    stamp: Literal["log", "header"] = Field("log", description="log: the bag's receive time; header: "
                                                   "header.stamp (the log time for messages without a header)")

    @model_validator(mode="after")
    def _split_needs(self) -> "Episodes":
        if self.split == "marker" and not self.marker_topic:
            raise ValueError("split = 'marker' needs marker_topic")
        if self.split == "gap" and self.gap_s is None:
            raise ValueError("split = 'gap' needs gap_s")
        return self


class Value(_Strict):
    """Where an episode's skill, label or onset comes from: a ``column`` (its first row; for an
    onset, the time of the first row where it is non-zero), the name of the ``folder`` holding the
    file (1) or of one above it (2, ...), a ``sidecar`` label pickle beside the file (its label;
    its time for an onset), a constant ``value``, or (a label) ``flag`` columns of true/false cells:
    the label is the name of the flag true first, its onset that row's time, none true a normal
    episode. ``pattern`` keeps a regex's first group of the text; ``missing`` stands in when the
    sidecar is not there."""

    column: str | None = None
    folder: int | None = Field(None, ge=1)
    sidecar: str | None = Field(None, min_length=1)
    value: str | None = None
    flag: list[str] | None = Field(None, min_length=1, description="a flag column's name, or several: each "
                                   "names the label it raises (TRUE/FALSE, 1/0, yes/no)")
    pattern: str | None = None
    missing: str | None = None

    @field_validator("flag", mode="before")
    @classmethod
    def _flags(cls, flag: Any) -> Any:
        return [flag] if isinstance(flag, str) else flag

    @model_validator(mode="after")
    def _one(self) -> "Value":
        given = [k for k in ("column", "folder", "sidecar", "value", "flag") if getattr(self, k) is not None]
        if len(given) != 1:
            raise ValueError(f"give one of column, folder, sidecar, value or flag, got {given or 'none'}")
        if self.missing is not None and self.sidecar is None:
            raise ValueError("missing is for a sidecar file that may not be there")
        return self

    @property
    def columns(self) -> list[str]:
        """The table columns it reads."""
        return self.flag or ([self.column] if self.column is not None else [])


class Dataset(Section):
    """A LeRobot dataset: nothing to set, its episodes come from episode_index."""

    kind: Literal["lerobot"] = "lerobot"
    address: ClassVar[Address] = "feature"


class Layout(_Strict):
    """How one file of a table is laid out: its format, header, time column and blank cells."""

    format: Literal["auto", "csv", "tsv", "whitespace", "parquet"] = Field(
        "auto", description="auto: by suffix (.csv, .tsv, .txt/.dat = whitespace, .parquet); whitespace: "
        "any run of spaces and tabs separates cells, trailing ones included")
    time_column: str | int | None = Field(None, description="the time column: its name, or its position from 0")
    time_unit: Literal["s", "ms", "us", "ns", "iso"] = Field(
        "s", description="iso: ISO-8601 text or a date-time column, its zone offset applied (none: UTC)")
    header: bool = Field(True, description="false: the file has no header line; its columns are names, or "
                         "else their positions as text (\"0\", \"1\", ...)")
    names: list[str] | None = Field(None, min_length=1, description="the columns of a headerless file, in order")
    blank: Literal["refuse", "drop_row", "hold"] = Field(
        "refuse", description="a blank cell (empty, NA, NaN, null) in a read column: refused naming the file and "
        "row, its row dropped, or the column's previous value held")

    @model_validator(mode="after")
    def _names_without_header(self) -> "Layout":
        if self.names is not None and self.header:
            raise ValueError("names are the columns of a file without a header line: set header = false")
        return self


class Part(Layout):
    """One file of each episode's folder, at its own rate and on its own clock (a sensor's log)."""

    files: str = Field(min_length=1, description="glob of the part's file in an episode's folder")
    columns: list[str] = Field(min_length=1, description="the columns read from it: channels' and labels'")

    @model_validator(mode="after")
    def _has_time(self) -> "Part":
        if self.time_column is None:
            raise ValueError(f"part {self.files!r} needs its time_column")
        return self


class Table(Section, Layout):
    """A lab's tables: which files, their layout, how they are cut into episodes and where labels
    come from; or, with ``parts``, one folder per episode holding one file per sensor."""

    kind: Literal["table"] = "table"
    address: ClassVar[Address] = "column"
    pads: ClassVar[bool] = True
    files: str = Field("**/*", description="glob of the tables under the source folder (a source that "
                       "is a file is read alone); with parts, of the episodes' folders (default: every "
                       "folder holding a part's file)")
    parts: list[Part] | None = Field(None, min_length=1, description="an episode is a folder of these files, "
                                     "joined on the model's clock, each resampled from its own time column")
    episode_column: str | None = Field(None, description="one table holds many episodes, told apart "
                                       "by this column (their rows contiguous); default: one per file")
    split: Literal["file", "gap"] = Field("file", description="gap: a pause longer than gap_s in a table's "
                                          "time also starts an episode (with episode_column too)")
    gap_s: float | None = Field(None, gt=0)
    phases: str | None = Field(None, min_length=1, description="a label pickle beside each table listing which "
                               "skill ran when, [(tag, (start, end)), ...]: one episode per phase with a tag > 0 "
                               "(its skill the tag unless skill says otherwise); rows outside them are not read")
    skill: Value | None = Field(None, description="default: the file's name (with parts, the folder's)")
    label: Value | None = Field(None, description="the anomaly label (default: none, a normal episode)")
    normal: list[str] = Field(["normal"], description="labels that mean a normal episode")
    onset: Value | None = None

    @model_validator(mode="after")
    def _one_split(self) -> "Table":
        if self.phases is not None and self.episode_column is not None:
            raise ValueError("give episode_column or phases, not both: each cuts a table into episodes")
        if self.phases is not None and self.split == "gap":
            raise ValueError("give split = 'gap' or phases, not both: each cuts a table into episodes")
        if self.split == "gap" and self.gap_s is None:
            raise ValueError("split = 'gap' needs gap_s")
        if (self.parts is None) == (self.time_column is None):
            raise ValueError("give time_column (one table per episode, or per episode_column value) or parts "
                             "(a folder per episode, a file per sensor, each with its time_column), not both")
        if self.parts is not None and (self.episode_column or self.phases or self.split == "gap"):
            raise ValueError("an episode of parts is a folder: no episode_column, phases or split = 'gap'")
        for name in ("skill", "onset"):
            if getattr(self, name) is not None and getattr(self, name).flag is not None:
                raise ValueError(f"flags give an episode's label and onset: {name} cannot be a flag")
        if self.label is not None and self.label.flag is not None and self.onset is not None:
            raise ValueError("a flag label has its onset at the flag's first true row: give no onset")
        return self

    @property
    def label_columns(self) -> list[str]:
        """The columns read as text: the skill's, the label's, the episode column."""
        values = [v for v in (self.skill, self.label) if v is not None and v.column is not None]
        return [*(v.column for v in values), *([self.episode_column] if self.episode_column else [])]  # type: ignore[misc]

    @property
    def flag_columns(self) -> list[str]:
        return [] if self.label is None or self.label.flag is None else self.label.flag

    @property
    def onset_column(self) -> str | None:
        return None if self.onset is None else self.onset.column

    def layout(self) -> list[str]:
        """What is read, in words: for ``nasm logs inspect``."""
        def file(lay: Layout, what: str) -> str:
            header = "a header line" if lay.header else f"no header, columns {lay.names or 'by position'}"
            return (f"{what} ({lay.format}, {header}), time in column {lay.time_column!r} ({lay.time_unit}), "
                    f"blank cells: {lay.blank}")
        if self.parts is not None:
            lines = [f"a folder per episode, {len(self.parts)} files each, joined on the model's clock (folders "
                     f"{self.files!r} under the source, or the source itself, holding a part):"]
            lines += ["  " + file(p, f"{p.files!r} -> {', '.join(p.columns)}") for p in self.parts]
        else:
            cut = ["an episode per file"] + ([f"per value of {self.episode_column!r}"] if self.episode_column else []) + (
                [f"a new one after each pause over {self.gap_s:g} s"] if self.split == "gap" else [])
            lines = [file(self, f"tables {self.files!r}"),
                     f"an episode per tagged phase of {self.phases!r}" if self.phases else ", ".join(cut)]
        labels = {"skill": self.skill, "label": self.label, "onset": self.onset}
        lines.append("; ".join(f"{k} from {v.model_dump(exclude_none=True)}" for k, v in labels.items() if v)
                     or "skill from the file's name, every episode normal")
        return lines


class Channel(_Strict):
    """One model channel: ``topic`` + ``field`` in a bag, ``feature`` in a LeRobot dataset, or a
    table's ``column``."""

    name: str = Field(min_length=1)
    units: str = Field(min_length=1, description="the channel's units, e.g. rad, m, N, N m, or 1")
    joint: bool = Field(False, description="a joint angle: a candidate for fault isolation")
    topic: str | None = None
    field: str | None = Field(None, description="dotted path in the message, e.g. position or wrench.force.x")
    feature: str | None = None
    column: str | None = None
    index: int | None = Field(None, ge=0, description="element of an array field or vector feature")
    key: str | None = Field(None, description="element by name: the message's name[] (JointState) "
                            "or the feature's names in meta/info.json")
    scale: float = Field(1.0, description="value = recorded value x scale (e.g. 0.001 for mm to m)")
    interpolation: Literal["linear", "previous"] = "linear"

    @model_validator(mode="after")
    def _consistent(self) -> "Channel":
        if [self.topic, self.feature, self.column].count(None) != 2:
            raise ValueError("give one source: either topic (a bag) or feature (a LeRobot dataset) or column (a table)")
        if self.topic is not None and not self.field:
            raise ValueError("a topic channel needs field, e.g. 'position' or 'wrench.force.x'")
        if self.feature is not None and self.field is not None:
            raise ValueError("field is for topics; pick a feature's element with index or key")
        if self.column is not None and (self.field is not None or self.index is not None or self.key is not None):
            raise ValueError("a column channel reads its column whole: no field, index or key")
        if self.index is not None and self.key is not None:
            raise ValueError("give index or key, not both")
        if self.joint != self.name.startswith(JOINT_PREFIX):
            raise ValueError(f"joint channels, and only they, must be named {JOINT_PREFIX}...: "
                             "fault isolation picks joints by that prefix")
        return self

    @property
    def address(self) -> Address:
        """The field the channel is read by."""
        return "topic" if self.topic is not None else "feature" if self.feature is not None else "column"

    @property
    def source(self) -> str:
        """Where the channel is read, for messages."""
        if self.column is not None:
            return f"column {self.column}"
        return f"{self.topic} {self.field}" if self.topic is not None else f"feature {self.feature}"


class Mapping(_Strict):
    description: str = ""
    timing: Timing
    source: Section = Field(description="the format's section; its kind names the format")
    channels: list[Channel] = Field(min_length=1)

    @model_validator(mode="before")
    @classmethod
    def _sections_before_source(cls, raw: Any) -> Any:
        """A mapping written before ``[source]``: ``[table]`` or ``[episodes]`` is its section, or
        without either, the channels' address names the format (features: a LeRobot dataset)."""
        if not isinstance(raw, dict) or "source" in raw:
            return raw
        raw = dict(raw)
        for key, kind in (("table", "table"), ("episodes", "rosbag")):
            if isinstance(raw.get(key), dict):
                raw["source"] = {"kind": kind, **raw.pop(key)}
                return raw
        channels = raw.get("channels")
        first = channels[0] if isinstance(channels, list) and channels and isinstance(channels[0], dict) else {}
        raw["source"] = {"kind": "lerobot" if "feature" in first else "table" if "column" in first else "rosbag"}
        return raw

    @model_validator(mode="after")
    def _consistent(self) -> "Mapping":
        names = [c.name for c in self.channels]
        repeated = sorted({n for n in names if names.count(n) > 1})
        if repeated:
            raise ValueError(f"channel names must be unique; repeated: {repeated}")
        address = self.source.address
        other = next((c for c in self.channels if c.address != address), None)
        if other is not None:
            raise ValueError(f"a {self.kind} source's channels each name a {address}; channel {other.name!r} "
                             f"names a {other.address}: one mapping reads one kind of source")
        if self.timing.shorter == "hold" and not self.source.pads:
            raise ValueError(f"timing.shorter = 'hold' is for tables, not a {self.kind} source")
        split = self.source if isinstance(self.source, (Episodes, Table)) and self.source.split == "gap" else None
        if split is not None and split.gap_s is not None and split.gap_s <= self.timing.gap_limit_s:
            raise ValueError(f"{self.kind}.gap_s ({split.gap_s}) must exceed timing.max_gap_s ({self.timing.gap_limit_s}): "
                             "a silence that splits episodes cannot also be allowed inside one")
        ep = self.source if isinstance(self.source, Episodes) else None
        if ep is not None and ep.split == "gap" and ep.gap_s is not None and ep.label_tolerance_s >= ep.gap_s:
            raise ValueError(f"episodes.label_tolerance_s ({ep.label_tolerance_s}) must be below gap_s ({ep.gap_s}): "
                             "a label before an episode must come after the previous one")
        if isinstance(self.source, Table) and self.source.parts is not None:
            self._check_parts(self.source)
        return self

    def _check_parts(self, table: Table) -> None:
        """Every column read, a channel's or a label's, is in exactly one part."""
        held = [p.columns for p in table.parts or []]
        wanted = [c.column for c in self.channels] + table.label_columns + table.flag_columns + (
            [table.onset_column] if table.onset_column else [])
        for column in wanted:
            holders = [i for i, columns in enumerate(held) if column in columns]
            if len(holders) != 1:
                raise ValueError(f"column {column!r} is in {len(holders) or 'no'} parts' columns; name it in one")
        unused = [c for columns in held for c in columns if c not in wanted]
        if unused:
            raise ValueError(f"parts' columns {unused} are read by no channel or label")

    @property
    def kind(self) -> str:
        """The source's format, a key of the reader registry (``logs.formats``)."""
        return self.source.kind

    @property
    def channel_names(self) -> tuple[str, ...]:
        return tuple(c.name for c in self.channels)

    def to_dict(self) -> dict[str, Any]:
        return self.model_dump(mode="json", exclude_none=True)


@functools.lru_cache(maxsize=8)
def _schema(sections: tuple[type[Section], ...]) -> type[Mapping]:
    """The mapping whose ``source`` is one of ``sections``, told apart by ``kind``."""
    union = Annotated[Union[sections], Field(discriminator="kind")]  # type: ignore[valid-type]
    return create_model("Mapping", __base__=Mapping, source=(union, ...))


def _where(loc: tuple[Any, ...], raw: Any) -> str:
    """``channels[3] ('joint4').topic`` from a pydantic location; in the source section, without the
    union's tag, and named as the file names it (``table``, ``episodes`` in a mapping without ``[source]``)."""
    if loc[:1] == ("source",):
        legacy = next((k for k in ("table", "episodes") if isinstance(raw, dict) and "source" not in raw and k in raw),
                      "source")
        loc = (legacy, *loc[2:])
    text, node = "", raw
    for item in loc:
        if isinstance(item, int):
            node = node[item] if isinstance(node, list) and item < len(node) else None
            name = node.get("name") if isinstance(node, dict) else None
            text += f"[{item}]" + (f" ({name!r})" if name else "")
        else:
            node = node.get(item) if isinstance(node, dict) else None
            text += f".{item}" if text else str(item)
    return text or "mapping"


def parse_mapping(raw: Any, where: str) -> Mapping:
    """Validate a mapping document against the registered formats; every problem in one message."""
    from neural_asm.logs.formats import readers  # the registry knows this module's sections

    try:
        return _schema(tuple(r.section for r in readers())).model_validate(raw)
    except ValidationError as exc:
        problems = [f"  {_where(e['loc'], raw)}: {e['msg'].removeprefix('Value error, ')}" for e in exc.errors()]
        raise LogError(f"{where} is not a valid channel mapping:\n" + "\n".join(problems)) from None


def load_mapping(path: str | Path) -> Mapping:
    """Read and validate a TOML or YAML mapping file."""
    path = Path(path)
    try:
        text = path.read_text()
    except OSError as exc:
        raise LogError(f"cannot read the mapping {path}: {exc.strerror or exc}") from None
    try:
        if path.suffix == ".toml":
            raw = tomllib.loads(text)
        elif path.suffix in (".yaml", ".yml"):
            raw = yaml.safe_load(text)
        else:
            raise LogError(f"mapping {path}: use a .toml or .yaml file")
    except (tomllib.TOMLDecodeError, yaml.YAMLError) as exc:
        raise LogError(f"mapping {path} is not valid {path.suffix[1:].upper()}: {exc}") from None
    return parse_mapping(raw, str(path))


def check_checkpoint(mapping: Mapping, channel_names: Sequence[str], provenance: dict[str, Any],
                     same_length: bool = True) -> None:
    """Refuse data mapped otherwise than the checkpoint's training data (channels, units, clock and,
    with ``same_length``, the steps an episode is resampled to: a streamed session has no fixed length)."""
    mine, theirs = mapping.channel_names, tuple(channel_names)
    if mine != theirs:
        missing = [n for n in theirs if n not in mine]
        extra = [n for n in mine if n not in theirs]
        why = (f"missing {missing}" if missing else "") + ("; " if missing and extra else "") + (f"extra {extra}" if extra else "")
        raise LogError(f"the mapping gives channels {list(mine)} but the model expects {list(theirs)} "
                       f"({why or 'same channels, other order'})")
    trained = provenance.get("mapping")
    if not trained:
        return
    before = parse_mapping(trained, "the checkpoint's mapping")
    steps = mapping.timing.steps if same_length else before.timing.steps
    if (before.timing.period_s, before.timing.steps) != (mapping.timing.period_s, steps):
        raise LogError(f"the mapping resamples to {mapping.timing.steps} steps of {mapping.timing.period_s} s; "
                       f"the model was trained on {before.timing.steps} steps of {before.timing.period_s} s")
    for old, new in zip(before.channels, mapping.channels):
        if old.units != new.units:
            raise LogError(f"channel {new.name} is in {new.units!r} in the mapping but the model was trained "
                           f"on {old.units!r}")
