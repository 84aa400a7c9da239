"""One file of a lab's table, read in blocks of checked rows.

The file's columns come from its header line (a UTF-8 byte-order mark and spaces around names
ignored, so a mapping may name a column with or without them) or, for a file without one, from
the mapping (``names``, else positions "0", "1", ...). CSV/TSV are read by pyarrow's streaming
reader and Parquet by row groups' batches; whitespace-delimited text is split line by line here,
since pyarrow's reader takes one delimiter character and would read a run of tabs and spaces, or
a trailing one, as empty cells. Each block's cells are checked and converted: the time column to
seconds (numbers in a unit, or ISO-8601 text and date-time columns with their zone offsets
applied), the channels' columns to floats, flag columns (TRUE/FALSE, 1/0, yes/no) to booleans,
and blank cells (empty, NA, NaN, null) refused, their rows dropped or the previous value held,
as the mapping's ``blank`` says. Every error names the file and the row (data rows counted from 1).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any, Iterator

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc
import pyarrow.csv as pacsv
import pyarrow.parquet as pq

from neural_asm.logs.errors import LogError
from neural_asm.logs.formats import TABLE_SUFFIXES
from neural_asm.logs.mapping import TIME_UNITS, Layout

BATCH_ROWS = 65_536
TIME = "\x00time"  # the time column's key among a block's columns: no column's name
ZONES = ("UTC", None)  # ISO-8601 text with zone offsets, or without (read as UTC)
TRUE_WORDS = frozenset({"true", "1", "yes", "1.0"})
FALSE_WORDS = frozenset({"false", "0", "no", "0.0"})


@dataclass(frozen=True)
class Wanted:
    """The columns read from a file, as the mapping names them."""

    time: str | int
    channels: tuple[str, ...] = ()  # numbers, in the channels' order
    flags: tuple[str, ...] = ()  # true/false cells
    text: tuple[str, ...] = ()  # kept as read: skill, label and episode columns


@dataclass(frozen=True)
class Rows:
    """A block of checked rows: their numbers in the file (from 1), times (s), channels' values,
    flags and text cells."""

    number: np.ndarray
    t: np.ndarray
    values: np.ndarray  # (rows, channels)
    flags: np.ndarray  # (rows, flags), bool
    text: dict[str, np.ndarray]


def file_format(path: Path, layout: Layout) -> str:
    if layout.format != "auto":
        return layout.format
    if path.suffix.lower() not in TABLE_SUFFIXES:
        raise LogError(f"{path}: cannot tell the table's format from its suffix; set format")
    return TABLE_SUFFIXES[path.suffix.lower()]


class TableFile:
    """One file's columns and its blocks of checked rows."""

    def __init__(self, path: Path, layout: Layout) -> None:
        self.path, self.layout, self.fmt = path, layout, file_format(path, layout)
        if path.stat().st_size == 0:
            raise LogError(f"{path}: empty file")
        try:
            self.keys = self._keys()  # the columns' names in the file (pyarrow's, or positions for text)
        except (OSError, UnicodeDecodeError, pa.ArrowException) as exc:
            raise LogError(f"{path}: {str(exc).splitlines()[0]}") from None
        if not layout.header and self.fmt == "parquet":
            raise LogError(f"{path}: a Parquet file names its columns; header = false is for text")
        if layout.names is not None and len(layout.names) != len(self.keys):
            raise LogError(f"{path}: its rows have {len(self.keys)} cells, names gives {len(layout.names)}")
        self.names = [str(k).strip() for k in self.keys] if layout.names is None else layout.names
        self._by_name: dict[str, Any] = {}
        for name, key in zip(self.names, self.keys):
            self._by_name.setdefault(name.strip(), key)

    def _keys(self) -> list[Any]:
        if self.fmt == "parquet":
            self.parquet = pq.ParquetFile(self.path, pre_buffer=False)  # pre-buffering holds whole row groups
            return list(self.parquet.schema_arrow.names)
        if self.fmt == "whitespace":
            with self.path.open(encoding="utf-8-sig") as f:
                first = next((line.split() for line in f if line.strip()), [])
            if not first:
                raise LogError(f"{self.path}: no rows")
            return first if self.layout.header else list(range(len(first)))
        first = self._read_options(block_size=1 << 16)  # the names need one small block
        names = pacsv.open_csv(self.path, read_options=first, parse_options=self._parse_options()).schema.names
        return names if self.layout.header else list(range(len(names)))

    def _read_options(self, **kw: Any) -> pacsv.ReadOptions:
        return pacsv.ReadOptions(autogenerate_column_names=not self.layout.header, **kw)

    def _parse_options(self) -> pacsv.ParseOptions:
        return pacsv.ParseOptions(delimiter="\t" if self.fmt == "tsv" else ",")

    def key(self, name: str | int) -> Any:
        """The file's column named ``name`` (spaces around it ignored), or at position ``name``."""
        if isinstance(name, int):
            if name >= len(self.keys):
                raise LogError(f"{self.path}: no column at position {name}; it has {len(self.keys)}")
            return self.keys[name]
        if name.strip() not in self._by_name:
            raise LogError(f"{self.path}: no column {name.strip()!r}; its columns: {self.names}")
        return self._by_name[name.strip()]

    def rows(self, wanted: Wanted) -> Iterator[Rows]:
        """The file's rows in blocks, checked and converted; blank cells as ``blank`` says."""
        missing = [c.strip() for c in (*wanted.channels, *wanted.flags, *wanted.text) if c.strip() not in self._by_name]
        if missing:
            raise LogError(f"{self.path}: no column {missing}; its columns: {self.names}")
        keys = {TIME: self.key(wanted.time), **{c: self.key(c) for c in (*wanted.channels, *wanted.flags, *wanted.text)}}
        blanks = _Blanks(self.path, self.layout.blank)
        read = 0
        for block in self._blocks(keys, wanted):
            n = len(block[TIME])
            number = read + 1 + np.arange(n)
            read += n
            cells = _Cells(self.path, number)
            t = cells.seconds(block[TIME], self.layout.time_unit, str(wanted.time))
            values = np.empty((n, len(wanted.channels)))
            for j, c in enumerate(wanted.channels):
                values[:, j] = cells.floats(block[c], c.strip())
            flags, flag_blank = np.empty((n, len(wanted.flags)), bool), np.empty((n, len(wanted.flags)), bool)
            for j, c in enumerate(wanted.flags):
                flags[:, j], flag_blank[:, j] = cells.flags(block[c], c.strip())
            text = {c: _objects(block[c]) for c in wanted.text}
            yield blanks.apply(Rows(number, t, values, flags, text), flag_blank,
                               tuple(str(c).strip() for c in (wanted.time, *wanted.channels, *wanted.flags)))

    def _blocks(self, keys: dict[str, Any], wanted: Wanted) -> Iterator[dict[str, Any]]:
        """Blocks of the wanted columns as read (pyarrow arrays, or text's numpy arrays)."""
        columns = list(dict.fromkeys(keys.values()))
        try:
            if self.fmt == "parquet":
                for batch in self.parquet.iter_batches(batch_size=BATCH_ROWS, columns=columns):
                    yield {k: batch.column(key) for k, key in keys.items()}
            elif self.fmt in ("csv", "tsv"):
                yield from self._csv_blocks(keys, wanted)
            else:
                yield from self._text_blocks(keys)
        except pa.ArrowException as exc:
            raise LogError(f"{self.path}: {str(exc).splitlines()[0]}") from None

    def _csv_blocks(self, keys: dict[str, Any], wanted: Wanted) -> Iterator[dict[str, Any]]:
        generated = [f"f{i}" for i in range(len(self.keys))]  # pyarrow's names for a headerless file's columns
        name = {k: (generated[k] if isinstance(k, int) else k) for k in keys.values()}
        types = {name[keys[c]]: pa.float64() for c in wanted.channels}
        types.update({name[keys[c]]: pa.string() for c in (*wanted.flags, *wanted.text)})
        if self.layout.time_unit == "iso":
            types[name[keys[TIME]]] = pa.string()
        convert = pacsv.ConvertOptions(include_columns=list(dict.fromkeys(name.values())), column_types=types)
        with pacsv.open_csv(self.path, read_options=self._read_options(block_size=1 << 22),
                            parse_options=self._parse_options(), convert_options=convert) as reader:
            for batch in reader:
                yield {k: batch.column(name[key]) for k, key in keys.items()}

    def _text_blocks(self, keys: dict[str, Any]) -> Iterator[dict[str, Any]]:
        index = {k: (key if isinstance(key, int) else self.keys.index(key)) for k, key in keys.items()}
        width = len(self.keys)
        with self.path.open(encoding="utf-8-sig") as f:
            rows: list[list[str]] = []
            read, skip = 0, self.layout.header
            for line in f:
                cells = line.split()
                if not cells:
                    continue
                if skip:
                    skip = False
                    continue
                if len(cells) != width:
                    raise LogError(f"{self.path}: row {read + len(rows) + 1} has {len(cells)} cells, the "
                                   f"{'header' if self.layout.header else 'first row'} {width}")
                rows.append(cells)
                if len(rows) == BATCH_ROWS:
                    yield _columns(rows, index)
                    read, rows = read + len(rows), []
            if rows:
                yield _columns(rows, index)


def _columns(rows: list[list[str]], index: dict[str, int]) -> dict[str, np.ndarray]:
    cells = np.array(rows, dtype=object)
    return {k: cells[:, i] for k, i in index.items()}


def _objects(column: Any) -> np.ndarray:
    return column if isinstance(column, np.ndarray) else np.asarray(column.to_pylist(), dtype=object)


class _Cells:
    """A block's cells converted, errors naming the file, the column and the row."""

    def __init__(self, path: Path, number: np.ndarray) -> None:
        self.path, self.number = path, number

    def where(self, i: int, column: str) -> str:
        return f"{self.path}: row {int(self.number[i])}, column {column!r}"

    def floats(self, column: Any, name: str) -> np.ndarray:
        """Numbers as floats, a blank as NaN; text refused."""
        if isinstance(column, np.ndarray):
            try:
                return column.astype(np.float64)
            except ValueError:
                bad = next(i for i, cell in enumerate(column) if not _is_float(cell))
                raise LogError(f"{self.where(bad, name)}: {column[bad]!r} is not a number") from None
        if pa.types.is_integer(column.type) or pa.types.is_floating(column.type) or pa.types.is_boolean(column.type):
            return column.to_numpy(zero_copy_only=False).astype(np.float64)
        if pa.types.is_null(column.type):
            return np.full(len(column), np.nan)
        raise LogError(f"{self.path}: column {name!r} holds {column.type}, not numbers")

    def seconds(self, column: Any, unit: str, name: str) -> np.ndarray:
        """Times in seconds: numbers in ``unit``, or ISO-8601 text and date-times (``unit = "iso"``)."""
        if unit != "iso":
            if not isinstance(column, np.ndarray) and (pa.types.is_string(column.type) or
                                                       pa.types.is_timestamp(column.type)):
                raise LogError(f"{self.path}: time column {name!r} holds {column.type}; for ISO-8601 times or "
                               "date-times set time_unit = \"iso\"")
            return self.floats(column, name) * TIME_UNITS[unit]
        if isinstance(column, np.ndarray):
            column = pa.array(column, pa.string())
        if pa.types.is_timestamp(column.type):
            stamps = column.cast(pa.timestamp("ns", column.type.tz))
        elif pa.types.is_string(column.type) or pa.types.is_large_string(column.type):
            stamps = self._parsed(column, name)
        else:
            raise LogError(f"{self.path}: time column {name!r} holds {column.type}, not ISO-8601 text or date-times")
        return stamps.cast(pa.int64()).to_numpy(zero_copy_only=False).astype(np.float64) * 1e-9

    def _parsed(self, column: pa.Array, name: str) -> pa.Array:
        """ISO-8601 text as UTC time stamps: with zone offsets (``Z``, ``+01:00``) or, all of them, without (UTC)."""
        for zone in ZONES:
            stamps = _stamps(column, zone)
            if stamps is not None:
                return stamps
        first: tuple[int, str | None] | None = None  # the first time's row and zone
        for i, cell in enumerate(column.to_pylist()):
            zone = next((z for z in ZONES if cell is None or _stamps(pa.array([cell]), z) is not None), "none")
            if zone == "none":
                raise LogError(f"{self.where(i, name)}: {cell!r} is not an ISO-8601 time")
            if cell is not None and first is not None and zone != first[1]:
                raise LogError(f"{self.where(i, name)}: {cell!r} has {'a' if zone else 'no'} zone offset, "
                               f"row {int(self.number[first[0]])}'s {'has' if first[1] else 'has none'}")
            first = first or ((i, zone) if cell is not None else None)
        raise LogError(f"{self.path}: time column {name!r} is not ISO-8601")

    def flags(self, column: Any, name: str) -> tuple[np.ndarray, np.ndarray]:
        """A flag column as (true, blank): TRUE/FALSE, 1/0, yes/no in any case; other text refused."""
        if not isinstance(column, np.ndarray) and (pa.types.is_boolean(column.type) or pa.types.is_integer(column.type)
                                                   or pa.types.is_floating(column.type)):
            column = column.cast(pa.string())
        words = [None if cell is None else str(cell).strip().lower() for cell in _objects(column)]
        blank = np.array([w is None or w in ("", "na", "nan", "null") for w in words], dtype=bool)
        true = np.array([w in TRUE_WORDS for w in words], dtype=bool)
        bad = [i for i, w in enumerate(words) if not blank[i] and not true[i] and w not in FALSE_WORDS]
        if bad:
            raise LogError(f"{self.where(bad[0], name)}: flag {_objects(column)[bad[0]]!r} is not TRUE/FALSE, "
                           "1/0 or yes/no")
        return true, blank


def _is_float(cell: str) -> bool:
    try:
        float(cell)
    except ValueError:
        return False
    return True


def _stamps(text: pa.Array, zone: str | None) -> pa.Array | None:
    """ISO-8601 text as time stamps: with zone offsets (``zone`` UTC) or without (``zone`` None); None if not."""
    try:
        return pc.cast(text, pa.timestamp("ns", zone))
    except pa.ArrowInvalid:
        return None


class _Blanks:
    """The ``blank`` policy over a file's blocks (``hold`` carries each column's last value across them)."""

    def __init__(self, path: Path, policy: str) -> None:
        self.path, self.policy = path, policy
        self.last: np.ndarray | None = None  # hold: the last values and flags

    def apply(self, rows: Rows, flag_blank: np.ndarray, columns: tuple[str, ...]) -> Rows:
        numbers = np.column_stack([rows.t, rows.values])
        if not np.isfinite(numbers).all() or flag_blank.any():
            inf = np.isinf(numbers)
            if inf.any():
                r, c = np.argwhere(inf)[0]
                raise LogError(f"{self.path}: row {int(rows.number[r])}, column {columns[c]!r}: inf")
            rows = self._blanks(rows, np.column_stack([np.isnan(numbers), flag_blank]), columns)
        if self.policy == "hold" and len(rows.t):
            self.last = np.column_stack([rows.t, rows.values, rows.flags])[-1:]
        return rows

    def _blanks(self, rows: Rows, blank: np.ndarray, columns: tuple[str, ...]) -> Rows:
        if self.policy == "drop_row":
            keep = ~blank.any(axis=1)
            return Rows(rows.number[keep], rows.t[keep], rows.values[keep], rows.flags[keep],
                        {k: v[keep] for k, v in rows.text.items()})
        if self.policy == "refuse" or blank[:, 0].any():
            r, c = np.argwhere(blank)[0]
            why = "a blank cell" + (" (blank = 'hold' holds no time)" if self.policy == "hold" else "")
            raise LogError(f"{self.path}: row {int(rows.number[r])}, column {columns[c]!r}: {why}")
        return self._held(rows, np.column_stack([rows.t, rows.values, rows.flags]), blank, columns)

    def _held(self, rows: Rows, values: np.ndarray, blank: np.ndarray, columns: tuple[str, ...]) -> Rows:
        """Each blank cell takes its column's previous value (from an earlier block if need be)."""
        if self.last is not None:
            values, blank = np.vstack([self.last, values]), np.vstack([np.zeros_like(blank[:1]), blank])
        source = np.where(blank, -1, np.arange(len(values))[:, None])
        source = np.maximum.accumulate(source, axis=0)
        if (source < 0).any():
            r, c = np.argwhere(source < 0)[0]
            raise LogError(f"{self.path}: row {int(rows.number[r])}, column {columns[c]!r}: a blank cell with "
                           "no value before it to hold")
        held = np.take_along_axis(values, source, axis=0)[len(values) - len(rows.t):]
        self.last = held[-1:]
        k = rows.values.shape[1]
        return Rows(rows.number, held[:, 0], held[:, 1:1 + k], held[:, 1 + k:].astype(bool), rows.text)
