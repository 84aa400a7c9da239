"""A lab's tables (CSV/TSV, whitespace-delimited text, Parquet) as episodes on the model's clock.

One file per episode, or one table cut into episodes by an ``episode_column`` (their rows
contiguous), by pauses in its time (``split = "gap"``; with an episode column, both), or by a
sidecar saying which skill ran when (``phases``); or, with ``parts``, one folder per episode
holding one file per sensor, each at its own rate and on its own clock, joined on the model's
clock. Files are read in blocks of checked rows (``logs.table_file``) and each block goes
straight into its episode's resampler (``logs.resample``, one stream per part), so a table larger
than memory is read in bounded memory. Each episode's skill, anomaly label and onset come from a
column, flag columns, the folder's name or a sidecar label pickle (``logs.label_pickle``).

Bad input (a malformed row, a mapped column missing, time not increasing, a blank cell refused,
a flag that is not true or false, an empty file, a part missing from a folder, a label pickle
holding anything but a label) is a LogError naming the file (and row), or with ``skip_bad`` a
warning and the next file or folder.
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any, Iterator

import numpy as np

from neural_asm.logs.errors import LogError
from neural_asm.logs.formats import TABLE_SUFFIXES as SUFFIXES
from neural_asm.logs.label_pickle import Phase, read_anomaly, read_phases
from neural_asm.logs.mapping import Mapping, Part, Table, Value
from neural_asm.logs.recorded import Recorded
from neural_asm.logs.resample import EpisodeResampler, Group
from neural_asm.logs.table_file import Rows, TableFile, Wanted


def table_files(source: Path, table: Table) -> list[Path]:
    """The tables of a source: the file itself, or the folder's files matching ``table.files``."""
    if source.is_file():
        return [source]
    files = sorted(p for p in source.glob(table.files) if p.is_file() and
                   (table.format != "auto" or p.suffix.lower() in SUFFIXES))
    if not files:
        raise LogError(f"no table matches {table.files!r} under {source}")
    return files


def episode_folders(source: Path, table: Table) -> list[Path]:
    """The episodes' folders: the source, or the folders under it matching ``table.files``, that hold a part's file."""
    if source.is_file():
        raise LogError(f"{source} is a file; an episode of parts is a folder")
    candidates = [source, *sorted(p for p in source.glob(table.files) if p.is_dir())]
    folders = [f for f in candidates if any(_part_files(f, part) for part in table.parts or [])]
    if not folders:
        raise LogError(f"no folder under {source} holds a file matching {[p.files for p in table.parts or []]}")
    return folders


def _part_files(folder: Path, part: Part) -> list[Path]:
    return sorted(p for p in folder.glob(part.files) if p.is_file())


def _cell_text(cell: Any) -> str:
    """A cell as text: 12.0 read from a numeric column is "12"."""
    return str(int(cell)) if isinstance(cell, (float, np.floating)) and float(cell).is_integer() else str(cell)


class _Episode:
    """One episode as it is read: its resampler, each file's last time (and each stream's last
    values, to pad with), its label columns' first cells and its flags' first true times."""

    def __init__(self, key: Any, what: str, groups: list[Group], mapping: Mapping, files: list[Path],
                 segment: int = 0) -> None:
        self.key, self.what, self.files, self.segment = key, what, files, segment  # segment: after how many pauses
        self.resampler = EpisodeResampler(groups, mapping.timing, what)
        self.last_t = [-np.inf] * len(files)
        self.last_values: list[np.ndarray | None] = [None] * len(groups)
        self.stream_t = [-np.inf] * len(groups)
        self.first: dict[str, Any] = {}
        self.raised: dict[str, float] = {}  # each flag's first true time
        self.skill: str | None = None  # a tagged phase's tag

    def add(self, file: int, stream: int | None, rows: Rows, flags: tuple[str, ...], a: int = 0, b: int | None = None) -> None:
        """Rows ``a:b`` of a block of file ``file``, into resampler stream ``stream`` (None: labels only)."""
        b = len(rows.t) if b is None else b
        if b <= a:
            return
        t = rows.t[a:b]
        step = np.diff(np.concatenate([[self.last_t[file]], t]))
        if (step <= 0).any():
            i = int(np.flatnonzero(step <= 0)[0])
            before = self.last_t[file] if i == 0 else t[i - 1]
            raise LogError(f"{self.files[file]}: row {int(rows.number[a + i])}: time does not increase ({t[i]:.6f} s "
                           f"after {before:.6f} s)")
        for c, cells in rows.text.items():
            self.first.setdefault(c, cells[a])
        for j, name in enumerate(flags):
            hit = np.flatnonzero(rows.flags[a:b, j])
            if name not in self.raised and len(hit):
                self.raised[name] = float(t[hit[0]])
        self.last_t[file] = float(t[-1])
        if stream is not None:
            self.resampler.add(stream, t, values=rows.values[a:b])
            self.last_values[stream], self.stream_t[stream] = rows.values[b - 1], float(t[-1])

    def data(self, mapping: Mapping) -> tuple[np.ndarray, float, float]:
        """Its values on the model's clock, its start and own length (s); a stream that ends
        early is padded by holding its last sample (``timing.shorter = "hold"``)."""
        timing, grid = mapping.timing, self.resampler.grid
        length = min(self.stream_t) - float(grid[0]) if grid is not None else 0.0
        if timing.shorter == "hold" and grid is not None:
            for g, (last_t, last) in enumerate(zip(self.stream_t, self.last_values)):
                if last_t < grid[-1]:
                    pad = last_t + timing.period_s * np.arange(1, int(np.ceil((grid[-1] - last_t) / timing.period_s)) + 1)
                    self.resampler.add(g, pad, values=np.repeat(last[None], len(pad), axis=0))  # type: ignore[index]
        data = self.resampler.finish()
        return data, float(self.resampler.grid[0]), length  # type: ignore[index]


class TableEpisodes:
    """The episodes of one mapping's tables, read file by file (or folder by folder, with parts)."""

    def __init__(self, source: Path, mapping: Mapping) -> None:
        assert isinstance(mapping.source, Table)
        self.source, self.mapping, self.table = source, mapping, mapping.source
        self.flags = tuple(self.table.flag_columns) + ((self.table.onset_column,) if self.table.onset_column else ())
        self.number = 0

    def read(self, path: Path) -> Iterator[Recorded]:
        """The episodes of one table file."""
        table = self.table
        channels = tuple(c.column for c in self.mapping.channels)  # type: ignore[misc]
        wanted = Wanted(table.time_column, channels, self.flags, tuple(dict.fromkeys(table.label_columns)))  # type: ignore[arg-type]
        group = Group("table rows", tuple(self.mapping.channels), tuple(range(len(channels))))
        phases = self._phases(path)
        gap = table.gap_s if table.split == "gap" else None
        open_: _Episode | None = None
        seen: set[Any] = set()
        for rows in TableFile(path, table).rows(wanted):
            n = len(rows.t)
            if n == 0:
                continue
            keys = rows.text[table.episode_column] if table.episode_column else (
                None if phases is None else phase_keys(rows.t, phases))
            new = np.zeros(n, dtype=bool)
            if keys is not None:
                new[1:] = keys[1:] != keys[:-1]
            if gap is not None:
                new[1:] |= np.diff(rows.t) > gap
            key = None if keys is None else keys[0]
            new[0] = open_ is None or key != open_.key or (gap is not None and rows.t[0] - open_.last_t[0] > gap)
            bounds = np.flatnonzero(new).tolist()
            for a, b in zip([0, *bounds], [*bounds, n]):
                key = None if keys is None else keys[a]
                if b <= a or (phases is not None and key < 0):  # between tagged phases
                    continue
                if new[a] or open_ is None:
                    if open_ is not None:
                        yield self._finish(open_, path)
                    open_ = self._next(open_, key, seen, path, [group])
                    open_.skill = None if phases is None else str(phases[key].tag)
                open_.add(0, 0, rows, self.flags, a, b)
        if open_ is None:
            raise LogError(f"{path}: no data rows" + ("" if phases is None else " in a tagged phase"))
        yield self._finish(open_, path)

    def _next(self, before: _Episode | None, key: Any, seen: set[Any], path: Path, groups: list[Group]) -> _Episode:
        """The episode starting at a new key (refused if the key was seen before) or after a pause."""
        if before is not None and key == before.key:
            return self._open(path, key, groups, before.segment + 1)
        if key in seen and key is not None:
            raise LogError(f"{path}: the rows of episode {_cell_text(key)} are not contiguous")
        seen.add(key)
        return self._open(path, key, groups, 0)

    def _open(self, path: Path, key: Any, groups: list[Group], segment: int) -> _Episode:
        what = f"{path}" + ("" if key is None else f", episode {_cell_text(key)}") + (
            f", segment {segment}" if self.table.split == "gap" else "")
        return _Episode(key, what, groups, self.mapping, [path], segment)

    def read_folder(self, folder: Path) -> Recorded:
        """The episode of one folder of parts: each file a stream of the resampler (a part with no
        channel: flags or labels only); a part missing, or matched by several files, is refused."""
        files = []
        for part in self.table.parts or []:
            found = _part_files(folder, part)
            if len(found) != 1:
                many = f"{len(found)} files ({', '.join(f.name for f in found)}) match" if found else "no file matches"
                raise LogError(f"{folder}: {many} part {part.files!r}; an episode has one file of each part")
            files.append(found[0])
        columns = [c.column for c in self.mapping.channels]
        groups: list[Group] = []
        reads = []
        for part, path in zip(self.table.parts or [], files):
            mine = tuple(c for c in part.columns if c in columns)
            places = tuple(columns.index(c) for c in mine)
            stream = len(groups) if mine else None
            if mine:
                groups.append(Group(f"part {path.name}", tuple(self.mapping.channels[i] for i in places), places))
            flags = tuple(c for c in self.flags if c in part.columns)
            text = tuple(c for c in self.table.label_columns if c in part.columns)
            blocks = TableFile(path, part).rows(Wanted(part.time_column, mine, flags, text))  # type: ignore[arg-type]
            reads.append((blocks, stream, flags))
        episode = _Episode(None, str(folder), groups, self.mapping, files)
        for whole in (False, True):  # a block of each file first: the clock is set and no file waits whole
            for i, (blocks, stream, flags) in enumerate(reads):
                for rows in blocks:
                    episode.add(i, stream, rows, flags)
                    if not whole and len(rows.t):
                        break
        return self._finish(episode, files[0])

    def _phases(self, path: Path) -> list[Phase] | None:
        """The tagged phases (tag > 0) of the sidecar beside ``path``, in time order; None without ``phases``."""
        if self.table.phases is None:
            return None
        sidecar = path.parent / self.table.phases
        if not sidecar.exists():
            raise LogError(f"{path}: no phase file {self.table.phases} beside it")
        return sorted((p for p in read_phases(sidecar) if p.tag > 0), key=lambda p: p.start_s)

    def _finish(self, ep: _Episode, path: Path) -> Recorded:
        """The episode read; ``path`` its (first) file, where folder and sidecar labels are found."""
        data, start, length = ep.data(self.mapping)
        parts = self.table.parts is not None
        skill = self._text(self.table.skill, ep, path) or ep.skill or (path.parent.name if parts else path.stem)
        anomaly, onset = self._anomaly(ep, path)
        number, self.number = self.number, self.number + 1
        where = path.parent if parts else path
        origin = str(where.relative_to(self.source)) if where != self.source and self.source.is_dir() else where.name
        origin += "" if ep.key is None else f" episode {_cell_text(ep.key)}"
        origin += f" segment {ep.segment}" if self.table.split == "gap" else ""
        return Recorded(data, skill, origin, start, number, anomaly, None if onset is None else onset - start, length)

    def _anomaly(self, ep: _Episode, path: Path) -> tuple[str | None, float | None]:
        """The anomaly label and its onset (on the source's clock): the flag raised first, or as label and onset say."""
        label = self.table.label
        if label is not None and label.flag is not None:
            raised = sorted((t, label.flag.index(name), name) for name, t in ep.raised.items() if name in label.flag)
            return (raised[0][2], raised[0][0]) if raised else (None, None)
        text = self._text(label, ep, path)
        return (None if text is None or text in self.table.normal else text), self._onset(ep, path)

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
            return ep.raised.get(onset.column)
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
    """Every episode of the source's tables (or folders of parts); strings are warnings (``skip_bad``)."""
    assert isinstance(mapping.source, Table)
    reader = TableEpisodes(source, mapping)
    parts = mapping.source.parts is not None
    for path in episode_folders(source, mapping.source) if parts else table_files(source, mapping.source):
        what = "folder" if parts else "file"
        try:
            if parts:
                yield reader.read_folder(path)
            else:
                yield from reader.read(path)
        except LogError as exc:
            if not skip_bad:
                raise LogError(f"{exc} (--skip-bad skips this {what})") from None
            if parts:
                reader.number += 1  # a skipped folder keeps its number: later episodes do not shift
            yield f"skipped {path}: {exc}"
