"""LeRobot datasets on disk, v2.x and v3.0 layouts, read with pyarrow.

``meta/info.json`` names the features (dtype, shape, element names), the frame rate and the
``data_path`` template of the parquet files: one file per episode in v2.x
(``data/chunk-000/episode_000000.parquet``), several episodes per file in v3.0
(``data/chunk-000/file-000.parquet``). Every frame row carries ``episode_index``,
``frame_index`` and ``timestamp`` (s from the episode's start); episodes are cut by
``episode_index`` in either layout. Skill names come from the task of the episode's first
frame (``meta/tasks.jsonl`` in v2.x, ``meta/tasks.parquet`` in v3.0).

Files are read one at a time. What was read is checked against the episodes the dataset
declares (``meta/episodes.jsonl``, ``meta/episodes/``, or ``total_episodes``) and their frame
counts: a missing or short episode is an error, or with ``skip_bad`` a warning naming it.
"""

from __future__ import annotations

import json
import re
from pathlib import Path
from typing import Any, Iterator

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from neural_asm.logs.errors import LogError
from neural_asm.logs.formats import LEROBOT_INFO as INFO
from neural_asm.logs.mapping import Channel, Mapping
from neural_asm.logs.recorded import Recorded
from neural_asm.logs.resample import EpisodeResampler, Group

TASKS_V2 = Path("meta/tasks.jsonl")
TASKS_V3 = Path("meta/tasks.parquet")
EPISODES_V2 = Path("meta/episodes.jsonl")
EPISODES_V3 = Path("meta/episodes")
READABLE = ("v2.", "v3.")
NON_NUMERIC = ("video", "image", "string")


def read_info(root: Path) -> dict[str, Any]:
    try:
        info = json.loads((root / INFO).read_text())
        version, features, data_path = info["codebase_version"], info["features"], info["data_path"]
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise LogError(f"{root / INFO} is not a LeRobot info.json: {exc}") from None
    if not str(version).startswith(READABLE) or not isinstance(features, dict) or not isinstance(data_path, str):
        raise LogError(f"{root}: LeRobot codebase_version {version!r}; this reads v2.x and v3.0 datasets")
    return info


def _names(feature: dict[str, Any]) -> list[str]:
    """Element names of a vector feature: a list, or (older datasets) a dict holding one list."""
    names = feature.get("names")
    if isinstance(names, dict) and len(names) == 1:
        names = next(iter(names.values()))
    return [str(n) for n in names] if isinstance(names, list) else []


def element(ch: Channel, features: dict[str, Any], root: Path) -> int | None:
    """Which element of its feature a channel reads (None: a scalar feature)."""
    where = f"dataset {root.name}, channel {ch.name}"
    feature = features.get(ch.feature or "")
    if feature is None:
        raise LogError(f"{where}: no feature {ch.feature!r}; the dataset has {sorted(features)}")
    if feature.get("dtype") in NON_NUMERIC:
        raise LogError(f"{where}: feature {ch.feature!r} is of type {feature.get('dtype')}, not numbers")
    shape = tuple(feature.get("shape") or (1,))
    if len(shape) != 1:
        raise LogError(f"{where}: feature {ch.feature!r} has shape {list(shape)}; only vectors are read")
    if ch.key is not None:
        names = _names(feature)
        if ch.key not in names:
            raise LogError(f"{where}: feature {ch.feature!r} has no element named {ch.key!r}; its names: {names}")
        return names.index(ch.key)
    if ch.index is not None and ch.index >= shape[0]:
        raise LogError(f"{where}: feature {ch.feature!r} has {shape[0]} elements, index {ch.index} is past its end")
    if ch.index is None and shape[0] > 1:
        raise LogError(f"{where}: feature {ch.feature!r} has {shape[0]} elements; give index or key")
    return ch.index


def _matrix(column: pa.ChunkedArray, name: str) -> np.ndarray:
    """(rows, width) floats of a numeric or list-of-numbers column."""
    arr = column.combine_chunks()
    if pa.types.is_list(arr.type) or pa.types.is_large_list(arr.type) or pa.types.is_fixed_size_list(arr.type):
        lengths = np.asarray(arr.value_lengths() if not pa.types.is_fixed_size_list(arr.type)
                             else np.full(len(arr), arr.type.list_size))
        if len(arr) and (lengths != lengths[0]).any():
            raise LogError(f"column {name!r} holds vectors of different lengths")
        flat, width = arr.flatten(), int(lengths[0]) if len(arr) else 0
    else:
        flat, width = arr, 1
    if not (pa.types.is_integer(flat.type) or pa.types.is_floating(flat.type) or pa.types.is_boolean(flat.type)):
        raise LogError(f"column {name!r} holds {flat.type} values, not numbers")
    return np.asarray(flat.to_numpy(zero_copy_only=False), np.float64).reshape(len(arr), width)


def _tasks(root: Path) -> dict[int, str]:
    if (root / TASKS_V2).exists():
        rows = [json.loads(line) for line in (root / TASKS_V2).read_text().splitlines() if line.strip()]
        return {int(r["task_index"]): str(r["task"]) for r in rows}
    if (root / TASKS_V3).exists():
        table = pq.read_table(root / TASKS_V3)
        index = (table.schema.pandas_metadata or {}).get("index_columns", [])
        text = "task" if "task" in table.column_names else next((c for c in index if isinstance(c, str)), None)
        if text is not None:
            return dict(zip(table.column("task_index").to_pylist(), map(str, table.column(text).to_pylist())))
    return {}


def _data_files(root: Path, template: str) -> list[Path]:
    files = sorted(root.glob(re.sub(r"\{[^}]*\}", "*", template)))
    if not files:
        raise LogError(f"dataset {root}: no parquet files match data_path {template!r}")
    return files


def declared_episodes(root: Path, info: dict[str, Any]) -> tuple[dict[int, int | None], str]:
    """The episodes the dataset says it has, with their frame counts where it says them, and where it says so."""
    try:
        if (root / EPISODES_V2).exists():
            rows = [json.loads(line) for line in (root / EPISODES_V2).read_text().splitlines() if line.strip()]
            return {int(r["episode_index"]): int(r["length"]) for r in rows}, str(EPISODES_V2)
        files = sorted((root / EPISODES_V3).glob("*/*.parquet"))
        if files:
            table = pa.concat_tables([pq.read_table(f, columns=["episode_index", "length"]) for f in files])
            return dict(zip(map(int, table.column("episode_index").to_pylist()),
                            map(int, table.column("length").to_pylist()))), f"{EPISODES_V3}/"
    except (OSError, ValueError, KeyError, TypeError, pa.ArrowException) as exc:
        raise LogError(f"dataset {root}: cannot read its episode list: {exc}") from None
    return dict.fromkeys(range(int(info.get("total_episodes", 0))), None), "total_episodes in meta/info.json"


def _expected_file(info: dict[str, Any], episode: int) -> str:
    """The v2.x file of an episode (v3.0 files hold several)."""
    try:
        return info["data_path"].format(episode_chunk=episode // int(info.get("chunks_size", 1000)), episode_index=episode)
    except (KeyError, IndexError, ValueError):
        return ""


def _episode(root: Path, mapping: Mapping, index: list[int | None], rows: dict[str, np.ndarray], number: int,
             length: int | None, label: str) -> Recorded:
    what = f"dataset {root.name}, episode {number}"
    if length is not None and len(rows["timestamp"]) != length:
        raise LogError(f"{what} has {len(rows['timestamp'])} frames; the dataset declares {length}")
    group = Group("dataset rows", tuple(mapping.channels), tuple(range(len(mapping.channels))))
    resampler = EpisodeResampler([group], mapping.timing, what)
    values = np.stack([rows[ch.feature][:, i or 0] for ch, i in zip(mapping.channels, index)], axis=1)  # type: ignore[index]
    resampler.add(0, rows["timestamp"].astype(np.float64), values=values)
    return Recorded(resampler.finish(), label, what, float(rows["timestamp"][0]), number)


def _file_rows(path: Path, features: list[str]) -> pa.Table:
    try:
        table = pq.read_table(path)
    except (OSError, pa.ArrowException) as exc:
        raise LogError(f"cannot read {path}: {exc}") from None
    missing = [c for c in ("episode_index", "frame_index", "timestamp", *features) if c not in table.column_names]
    if missing:
        raise LogError(f"{path} has no column {missing}; its columns: {table.column_names}")
    return table


def read_episodes(root: Path, mapping: Mapping, skip_bad: bool = False) -> Iterator[Recorded | str]:
    """Each episode of the dataset (by episode_index), read file by file and resampled to the
    model's clock; checked against the episodes the dataset declares. Strings are warnings."""
    info = read_info(root)
    index = [element(ch, info["features"], root) for ch in mapping.channels]
    features = sorted({ch.feature for ch in mapping.channels if ch.feature})
    declared, where = declared_episodes(root, info)
    tasks = _tasks(root)
    seen: set[int] = set()
    for path in _data_files(root, info["data_path"]):
        try:
            table = _file_rows(path, features)
        except LogError as exc:
            if not skip_bad:
                raise
            yield f"skipped {path.relative_to(root)}: {exc}"
            continue
        episode = table.column("episode_index").to_numpy()
        order = np.lexsort((table.column("frame_index").to_numpy(), episode))
        episode = episode[order]
        columns = {f: _matrix(table.column(f), f)[order] for f in features}
        columns["timestamp"] = _matrix(table.column("timestamp"), "timestamp")[order, 0]
        tasks_of = table.column("task_index").to_numpy()[order] if "task_index" in table.column_names else None
        for e in np.unique(episode):
            rows = np.flatnonzero(episode == e)
            number = int(e)
            seen.add(number)
            label = tasks.get(int(tasks_of[rows[0]]), "unknown") if tasks_of is not None else "unknown"
            try:
                yield _episode(root, mapping, index, {k: v[rows] for k, v in columns.items()}, number,
                               declared.get(number), label)
            except LogError as exc:
                if not skip_bad:
                    raise LogError(f"{exc} (--skip-bad skips this episode)") from None
                yield f"skipped episode {number}: {exc}"
    missing = sorted(set(declared) - seen)
    for number in missing if skip_bad else []:
        expected = _expected_file(info, number)
        yield (f"dataset {root.name}: episode {number} ({where}) has no rows in the data files"
               + (f" ({expected} is not there)" if expected and not (root / expected).exists() else ""))
    if missing and not skip_bad:
        files = [f for f in (_expected_file(info, n) for n in missing) if f and not (root / f).exists()]
        raise LogError(f"dataset {root.name}: episodes {missing} ({where}) have no rows in the data files"
                       + (f"; missing files: {files}" if files else "") + " (--skip-bad reads the others)")
