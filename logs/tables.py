"""A lab's tables (CSV/TSV, whitespace-delimited text, Parquet) as episodes on the model's clock.

One file per episode, or one table whose ``episode_column`` tells its episodes apart (their rows
contiguous). Files are read in blocks (Parquet by row groups' batches, CSV by pyarrow's streaming
reader, text line by line) and each block goes straight into its episode's resampler
(``logs.resample``), so a table larger than memory is read in bounded memory. Each episode's
skill, anomaly label and onset come from a column, the folder's name or a sidecar label pickle
(``logs.label_pickle``), as the mapping's ``[table]`` says. A whole run kept as one table with a
sidecar saying which skill ran when (``phases``) is read as one episode per tagged phase.

Bad input (a malformed row, a mapped column missing, time going backwards, NaN or inf, an empty
file, a label pickle holding anything but a label) is a LogError naming the file, or with
``skip_bad`` a warning and the next file.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterator

import numpy as np
import pyarrow as pa
import pyarrow.csv as pacsv
import pyarrow.parquet as pq

from neural_asm.logs.errors import LogError
from neural_asm.logs.formats import TABLE_SUFFIXES as SUFFIXES
from neural_asm.logs.label_pickle import Phase, read_anomaly, read_phases
from neural_asm.logs.mapping import TIME_UNITS, Mapping, Table, Value
from neural_asm.logs.recorded import Recorded
from neural_asm.logs.resample import EpisodeResampler, Group

BATCH_ROWS = 65_536
Block = dict[str, np.ndarray]


def table_files(source: Path, table: Table) -> list[Path]:
    """The tables of a source: the file itself, or the folder's files matching ``table.files``."""
    if source.is_file():
        return [source]
    files = sorted(p for p in source.glob(table.files) if p.is_file() and
                   (table.format != "auto" or p.suffix.lower() in SUFFIXES))
    if not files:
        raise LogError(f"no table matches {table.files!r} under {source}")
    return files


def _format(path: Path, table: Table) -> str:
    if table.format != "auto":
        return table.format
    if path.suffix.lower() not in SUFFIXES:
        raise LogError(f"{path}: cannot tell the table's format from its suffix; set table.format")
    return SUFFIXES[path.suffix.lower()]


def _numbers(column: Any) -> np.ndarray:
    """A block's numeric column as floats (an empty cell as NaN, refused later naming its row); text as objects."""
    if not (pa.types.is_integer(column.type) or pa.types.is_floating(column.type) or pa.types.is_boolean(column.type)):
        return np.asarray(column.to_pylist(), dtype=object)
    return column.to_numpy(zero_copy_only=False).astype(np.float64)


class _Reader:
    """One file's column names and its blocks of the wanted columns."""

    def __init__(self, path: Path, fmt: str) -> None:
        self.path, self.fmt = path, fmt
        if path.stat().st_size == 0:
            raise LogError(f"{path}: empty file")
        try:
            if fmt == "parquet":
                self.parquet = pq.ParquetFile(path, pre_buffer=False)  # pre-buffering holds whole row groups: peak memory
                self.names = list(self.parquet.schema_arrow.names)
            elif fmt in ("csv", "tsv"):
                self.names = pacsv.open_csv(path, parse_options=self._csv_options()).schema.names
            else:
                with path.open() as f:
                    header = f.readline().split()
                if not header:
                    raise LogError(f"{path}: no header line")
                self.names = header
        except (OSError, pa.ArrowException) as exc:
            raise LogError(f"{path}: {exc}") from None

    def _csv_options(self) -> pacsv.ParseOptions:
        return pacsv.ParseOptions(delimiter="\t" if self.fmt == "tsv" else ",")

    def blocks(self, columns: list[str]) -> Iterator[Block]:
        try:
            if self.fmt == "parquet":
                for batch in self.parquet.iter_batches(batch_size=BATCH_ROWS, columns=columns):
                    yield {c: _numbers(batch.column(c)) for c in columns}
            elif self.fmt in ("csv", "tsv"):
                convert = pacsv.ConvertOptions(include_columns=columns)
                with pacsv.open_csv(self.path, parse_options=self._csv_options(), convert_options=convert) as reader:
                    for batch in reader:
                        yield {c: _numbers(batch.column(c)) for c in columns}
            else:
                yield from self._text_blocks(columns)
        except pa.ArrowException as exc:
            raise LogError(f"{self.path}: {str(exc).splitlines()[0]}") from None

    def _text_blocks(self, columns: list[str]) -> Iterator[Block]:
        index = [self.names.index(c) for c in columns]
        with self.path.open() as f:
            f.readline()
            rows: list[list[str]] = []
            for line_no, line in enumerate(f, start=2):
                cells = line.split()
                if not cells:
                    continue
                if len(cells) != len(self.names):
                    raise LogError(f"{self.path}: line {line_no} has {len(cells)} fields, the header {len(self.names)}")
                rows.append([cells[i] for i in index])
                if len(rows) == BATCH_ROWS:
                    yield self._parsed(rows, columns, line_no)
                    rows = []
            if rows:
                yield self._parsed(rows, columns, line_no)

    def _parsed(self, rows: list[list[str]], columns: list[str], line_no: int) -> Block:
        cells = np.array(rows, dtype=object)
        out: Block = {}
        for j, c in enumerate(columns):
            try:
                out[c] = cells[:, j].astype(np.float64)
            except ValueError:
                out[c] = cells[:, j]
        return out


def _cell_text(cell: Any) -> str:
    """A cell as text: 12.0 read from a numeric column is "12"."""
    return str(int(cell)) if isinstance(cell, (float, np.floating)) and float(cell).is_integer() else str(cell)


@dataclass
class _Episode:
    key: Any
    what: str
    resampler: EpisodeResampler
    first: dict[str, Any] = field(default_factory=dict)  # skill/label columns at the first row
    onset_t: float | None = None
    skill: str | None = None  # a tagged phase's tag
    last_t: float = -np.inf
    last_values: np.ndarray | None = None


class TableEpisodes:
    """The episodes of one mapping's tables, read file by file."""

    def __init__(self, source: Path, mapping: Mapping) -> None:
        assert isinstance(mapping.source, Table)
        self.source, self.mapping, self.table = source, mapping, mapping.source
        self.group = Group("table rows", tuple(mapping.channels), tuple(range(len(mapping.channels))))
        self.number = 0

    def _columns(self, reader: _Reader) -> tuple[str, list[str], list[str]]:
        """The time column's name, the channels' columns and the label columns; a missing one is refused."""
        t = self.table.time_column
        if isinstance(t, int):
            if t >= len(reader.names):
                raise LogError(f"{reader.path}: no column at position {t}; it has {len(reader.names)}")
            t = reader.names[t]
        channels = [c.column for c in self.mapping.channels]
        labels = [v.column for v in (self.table.skill, self.table.label, self.table.onset) if v and v.column]
        if self.table.episode_column:
            labels.append(self.table.episode_column)
        missing = [c for c in [t, *channels, *labels] if c not in reader.names]
        if missing:
            raise LogError(f"{reader.path}: no column {missing}; its columns: {reader.names}")
        return t, channels, list(dict.fromkeys(labels))  # type: ignore[list-item]

    def read(self, path: Path) -> Iterator[Recorded]:
        reader = _Reader(path, _format(path, self.table))
        t_col, channels, label_cols = self._columns(reader)
        scale = TIME_UNITS[self.table.time_unit]
        wanted = list(dict.fromkeys([t_col, *channels, *label_cols]))
        ep_col = self.table.episode_column
        phases = self._phases(path)
        open_: _Episode | None = None
        seen: set[Any] = set()
        rows_read = 0
        for block in reader.blocks(wanted):
            t = np.asarray(block[t_col], np.float64) * scale if block[t_col].dtype != object else None
            if t is None:
                raise LogError(f"{path}: time column {t_col!r} holds text")
            values = np.empty((len(t), len(channels)))
            for j, c in enumerate(channels):
                if block[c].dtype == object:
                    raise LogError(f"{path}: column {c!r} holds text, not numbers")
                values[:, j] = block[c]
            bad = ~np.isfinite(values).all(axis=1) | ~np.isfinite(t)
            if bad.any():
                r = int(np.flatnonzero(bad)[0])
                cols = [c for j, c in enumerate(channels) if not np.isfinite(values[r, j])] or [t_col]
                raise LogError(f"{path}: NaN, inf or an empty cell in column {cols} at data row {rows_read + r + 1}")
            keys = block[ep_col] if ep_col else None if phases is None else phase_keys(t, phases)
            starts = [0] if keys is None else [0, *np.flatnonzero(keys[1:] != keys[:-1]) + 1]
            for a, b in zip(starts, [*starts[1:], len(t)]):
                key = None if keys is None else keys[a]
                if phases is not None and key < 0:  # between tagged phases
                    continue
                if open_ is None or key != open_.key:
                    if open_ is not None:
                        yield self._finish(open_, path)
                    if key in seen:
                        raise LogError(f"{path}: the rows of episode {_cell_text(key)} are not contiguous")
                    seen.add(key)
                    open_ = self._open(path, key)
                    open_.skill = None if phases is None else str(phases[key].tag)
                    open_.first = {c: block[c][a] for c in label_cols}
                self._add(open_, t[a:b], values[a:b], block, a, b)
            rows_read += len(t)
        if open_ is None:
            raise LogError(f"{path}: no data rows" + ("" if phases is None else " in a tagged phase"))
        yield self._finish(open_, path)

    def _phases(self, path: Path) -> list[Phase] | None:
        """The tagged phases (tag > 0) of the sidecar beside ``path``, in time order; None without ``phases``."""
        if self.table.phases is None:
            return None
        sidecar = path.parent / self.table.phases
        if not sidecar.exists():
            raise LogError(f"{path}: no phase file {self.table.phases} beside it")
        return sorted((p for p in read_phases(sidecar) if p.tag > 0), key=lambda p: p.start_s)

    def _open(self, path: Path, key: Any) -> _Episode:
        what = f"{path}" + ("" if key is None else f", episode {_cell_text(key)}")
        return _Episode(key, what, EpisodeResampler([self.group], self.mapping.timing, what))

    def _add(self, ep: _Episode, t: np.ndarray, values: np.ndarray, block: Block, a: int, b: int) -> None:
        onset = self.table.onset
        if onset is not None and onset.column and ep.onset_t is None:
            hit = np.flatnonzero(np.asarray(block[onset.column][a:b], np.float64) != 0)
            ep.onset_t = float(t[hit[0]]) if len(hit) else None
        ep.resampler.add(0, t, values=values)
        ep.last_t, ep.last_values = float(t[-1]), values[-1]

    def _finish(self, ep: _Episode, path: Path) -> Recorded:
        timing = self.mapping.timing
        grid = ep.resampler.grid
        length = ep.last_t - float(grid[0]) if grid is not None else 0.0
        if timing.shorter == "hold" and grid is not None and ep.last_t < grid[-1]:
            pad = ep.last_t + timing.period_s * np.arange(1, int(np.ceil((grid[-1] - ep.last_t) / timing.period_s)) + 1)
            ep.resampler.add(0, pad, values=np.repeat(ep.last_values[None], len(pad), axis=0))  # type: ignore[index]
        data = ep.resampler.finish()
        start = float(ep.resampler.grid[0])  # type: ignore[index]
        skill = self._text(self.table.skill, ep, path) or ep.skill or path.stem
        label = self._text(self.table.label, ep, path)
        anomaly = None if label is None or label in self.table.normal else label
        onset = self._onset(ep, path)
        number, self.number = self.number, self.number + 1
        origin = str(path.relative_to(self.source)) if path != self.source and self.source.is_dir() else path.name
        origin += "" if ep.key is None else f" episode {_cell_text(ep.key)}"
        return Recorded(data, skill, origin, start, number, anomaly, None if onset is None else onset - start, length)

    def _text(self, value: Value | None, ep: _Episode, path: Path) -> str | None:
        if value is None:
            return None
        if value.value is not None:
            text = value.value
        elif value.column is not None:
            text = _cell_text(ep.first[value.column])
        elif value.folder is not None:
            parents = path.parents
            if value.folder > len(parents) - 1:
                raise LogError(f"{path}: no folder {value.folder} levels up")
            text = parents[value.folder - 1].name
        else:
            sidecar = path.parent / value.sidecar  # type: ignore[operator]
            if not sidecar.exists():
                if value.missing is None:
                    raise LogError(f"{path}: no label file {value.sidecar} beside it")
                return value.missing
            text = read_anomaly(sidecar).label
        if value.pattern:
            match = re.search(value.pattern, text)
            if not match:
                raise LogError(f"{path}: {text!r} does not match the pattern {value.pattern!r}")
            text = match.group(1) if match.groups() else match.group(0)
        return text

    def _onset(self, ep: _Episode, path: Path) -> float | None:
        onset = self.table.onset
        if onset is None:
            return None
        if onset.column is not None:
            return ep.onset_t
        if onset.sidecar is not None:
            sidecar = path.parent / onset.sidecar
            return read_anomaly(sidecar).time_s if sidecar.exists() else None
        raise LogError("table.onset comes from a column or a sidecar label file")


def phase_keys(t: np.ndarray, phases: list[Phase]) -> np.ndarray:
    """(len(t),) the index of the phase holding each time (start <= t <= end), -1 outside every phase."""
    if not phases:
        return np.full(len(t), -1)
    starts = np.array([p.start_s for p in phases])
    ends = np.array([p.end_s for p in phases])
    index = np.searchsorted(starts, t, side="right") - 1
    inside = (index >= 0) & (t <= ends[np.maximum(index, 0)])
    return np.where(inside, index, -1)


def read_episodes(source: Path, mapping: Mapping, skip_bad: bool = False) -> Iterator[Recorded | str]:
    """Every episode of the source's tables; strings are warnings (``skip_bad``)."""
    assert isinstance(mapping.source, Table)
    reader = TableEpisodes(source, mapping)
    for path in table_files(source, mapping.source):
        try:
            yield from reader.read(path)
        except LogError as exc:
            if not skip_bad:
                raise LogError(f"{exc} (--skip-bad skips this file)") from None
            yield f"skipped {path}: {exc}"
