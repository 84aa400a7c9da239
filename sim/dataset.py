"""Episode sets and their files: MCAP as the source of truth, a `.npz` cache beside it.

A task's sets (`sim.paper`, `sim.varied_sets`) are simulated by `generate`. Every set of the
paper's task can be observed at 2 Hz or at 40 Hz: the rate is the episodes' `rate_hz`, and a set
folder holds one rate (`set_folder`).

File format, one `<set>.mcap` per set (JSON-schema channels, zstd chunks):

- topic `/episode` (schema `nasm.Episode`), one message per episode, log time = episode
  index x 7.5 s: `index, skill, seed, fault ({joint, time_s, overshoot_deg} or null),
  disturbance (or null), success, cube_error_m, channel_names, warnings, plan` (15 x 7 rad) and
  `hi_rate` (40 Hz `t, qpos, command, ee, cube, box` as float32 lists);
- topic `/observation` (schema `nasm.Observation`), one message per observation, log time =
  the episode's start + k / rate: `episode, step, time_s, values` (one float per channel, in
  the episode's `channel_names` order). `/episode` says the rate (`rate_hz`; absent: 2 Hz).

`<set>.npz` holds the same data as arrays (observations (N, T, D), ...) plus the MCAP's size
and mtime; `load_episodes` uses it only while it matches the MCAP, else decodes the MCAP.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np
import orjson
from mcap.reader import make_reader
from mcap.writer import Writer

from neural_asm.runtime.parallel import Backend
from neural_asm.sim.config import SIM
from neural_asm.sim.disturbances import FallingObject
from neural_asm.sim.episode import Episode
from neural_asm.sim.faults import FaultSpec
from neural_asm.sim.task import SetSizes, Task
from neural_asm.sim.varied_faults import VariedFault

HI_RATE = ("t_hi", "qpos_hi", "command_hi", "ee_hi", "cube_hi", "box_hi")
EPISODE_SCHEMA = {
    "title": "nasm.Episode", "type": "object",
    "properties": {"index": {"type": "integer"}, "skill": {"type": "string"}, "seed": {"type": "integer"},
                   "fault": {"type": ["object", "null"]}, "disturbance": {"type": ["object", "null"]},
                   "success": {"type": "boolean"}, "cube_error_m": {"type": "number"},
                   "channel_names": {"type": "array", "items": {"type": "string"}},
                   "warnings": {"type": "array"}, "plan": {"type": "array"}, "hi_rate": {"type": "object"},
                   "task": {"type": ["object", "null"]}, "rate_hz": {"type": "number"}},
}
OBSERVATION_SCHEMA = {
    "title": "nasm.Observation", "type": "object",
    "properties": {"episode": {"type": "integer"}, "step": {"type": "integer"}, "time_s": {"type": "number"},
                   "values": {"type": "array", "items": {"type": "number"}, "minItems": 1}},
}


def set_folder(rate: float) -> str:
    """The data home's folder of the paper task's sets observed at `rate`: `data` at 2 Hz, as
    ever, `data_40hz` at 40 Hz."""
    SIM.timing.ticks_per_observation(rate)  # a ValueError for a rate episodes cannot be observed at
    return "data" if rate == SIM.timing.observation_hz else f"data_{rate:g}hz"


def _meta(index: int, ep: Episode) -> dict:
    return {"index": index, "skill": ep.skill, "seed": ep.seed,
            "fault": None if ep.fault is None else ep.fault.to_dict(),
            "disturbance": None if ep.disturbance is None else ep.disturbance.to_dict(),
            "success": bool(ep.success), "cube_error_m": ep.cube_error_m, "channel_names": list(ep.channel_names),
            "warnings": ep.warnings, "task": ep.task, "rate_hz": ep.rate_hz}


def _episode_message(index: int, ep: Episode) -> dict:
    return {**_meta(index, ep), "plan": ep.plan,
            "hi_rate": {name: getattr(ep, name).astype(np.float32) for name in HI_RATE}}


def write_mcap(episodes: list[Episode], path: Path) -> None:
    """Write episodes to `path` (atomically: a temporary file renamed into place)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(".mcap.tmp")
    episode_ns = int(1e9 * SIM.timing.duration_s)
    with open(tmp, "wb") as f:
        writer = Writer(f)
        writer.start(profile="", library="neural-asm sim")
        ep_schema = writer.register_schema("nasm.Episode", "jsonschema", json.dumps(EPISODE_SCHEMA).encode())
        ob_schema = writer.register_schema("nasm.Observation", "jsonschema", json.dumps(OBSERVATION_SCHEMA).encode())
        ep_channel = writer.register_channel("/episode", "json", ep_schema)
        ob_channel = writer.register_channel("/observation", "json", ob_schema)
        for i, ep in enumerate(episodes):
            start = i * episode_ns
            writer.add_message(ep_channel, start, orjson.dumps(_episode_message(i, ep), option=orjson.OPT_SERIALIZE_NUMPY),
                               start, sequence=i)
            step_ns = round(1e9 / ep.rate_hz)
            for k, values in enumerate(ep.observations):
                msg = {"episode": i, "step": k, "time_s": k / ep.rate_hz, "values": values}
                writer.add_message(ob_channel, start + k * step_ns, orjson.dumps(msg, option=orjson.OPT_SERIALIZE_NUMPY),
                                   start + k * step_ns, sequence=k)
        writer.finish()
    os.replace(tmp, path)


def _episode_from(meta: dict, observations: np.ndarray) -> Episode:
    fault = meta["fault"]
    if fault is not None:
        fault = VariedFault.from_dict(fault) if "kind" in fault else FaultSpec(**fault)
    disturbance = meta["disturbance"]
    if disturbance is not None:
        disturbance = FallingObject(**{k: v for k, v in disturbance.items() if k != "kind"})
    hi = {name: np.asarray(meta["hi_rate"][name], dtype=np.float64) for name in HI_RATE}
    return Episode(observations=observations, skill=meta["skill"], seed=int(meta["seed"]),
                   fault=fault, disturbance=disturbance, task=meta.get("task"),
                   success=bool(meta["success"]), cube_error_m=float(meta["cube_error_m"]),
                   plan=np.asarray(meta["plan"], dtype=np.float64), channel_names=tuple(meta["channel_names"]),
                   warnings=list(meta["warnings"]), rate_hz=float(meta.get("rate_hz", SIM.timing.observation_hz)), **hi)


def read_episode_set(path: Path) -> list[Episode]:
    """Decode an episode set from its MCAP file."""
    metas: dict[int, dict] = {}
    values: dict[int, dict[int, list]] = {}
    with open(path, "rb") as f:
        for _, channel, message in make_reader(f).iter_messages(topics=["/episode", "/observation"]):
            msg = orjson.loads(message.data)
            if channel.topic == "/episode":
                metas[msg["index"]] = msg
            else:
                values.setdefault(msg["episode"], {})[msg["step"]] = msg["values"]
    return [_episode_from(metas[i], np.array([values[i][k] for k in sorted(values[i])], dtype=np.float64))
            for i in sorted(metas)]


def _stamp(mcap_path: Path) -> np.ndarray:
    stat = mcap_path.stat()
    return np.array([stat.st_size, stat.st_mtime_ns], dtype=np.int64)


def write_cache(episodes: list[Episode], mcap_path: Path) -> Path:
    """Write the `.npz` cache for `mcap_path` (metadata as one JSON string, 40 Hz traces as float32 like the MCAP)."""
    metas = [_meta(i, ep) for i, ep in enumerate(episodes)]
    arrays = {name: np.array([getattr(ep, name) for ep in episodes], dtype=np.float32) for name in HI_RATE}
    arrays |= {name: np.array([getattr(ep, name) for ep in episodes]) for name in ("plan", "observations")}
    path = mcap_path.with_suffix(".npz")
    tmp = path.with_suffix(".tmp.npz")
    np.savez(tmp, meta=np.array(orjson.dumps(metas, option=orjson.OPT_SERIALIZE_NUMPY).decode()),
             stamp=_stamp(mcap_path), **arrays)
    os.replace(tmp, path)
    return path


def _read_cache(path: Path) -> list[Episode]:
    with np.load(path) as z:
        metas = orjson.loads(str(z["meta"]))
        arrays = {name: z[name] for name in (*HI_RATE, "plan", "observations")}
    episodes = []
    for i, meta in enumerate(metas):
        meta = {**meta, "plan": arrays["plan"][i], "hi_rate": {name: arrays[name][i] for name in HI_RATE}}
        episodes.append(_episode_from(meta, arrays["observations"][i]))
    return episodes


def load_episodes(path: str | Path) -> list[Episode]:
    """Read a set back from `<set>.mcap` (through its cache when that is current) or `<set>.npz`."""
    path = Path(path)
    if path.suffix == ".npz":
        return _read_cache(path)
    cache = path.with_suffix(".npz")
    if cache.exists():
        with np.load(cache) as z:
            current = np.array_equal(z["stamp"], _stamp(path))
        if current:
            return _read_cache(cache)
    return read_episode_set(path)


def generate(task: Task, kind: str, out_dir: str | Path, sizes: SetSizes = SetSizes(), workers: int = 2,
             backend: Backend = "processes") -> tuple[Path, list[str]]:
    """Simulate `task`'s set `kind` (of `sizes`), write `<out_dir>/<kind>.mcap` and its cache;
    return the path and failures."""
    from neural_asm.sim.runner import run_jobs  # the simulator, only when simulating

    episodes, failures = run_jobs(task, task.jobs(kind, sizes), workers, desc=kind, backend=backend)
    path = Path(out_dir) / f"{kind}.mcap"
    write_mcap(episodes, path)
    write_cache(episodes, path)
    return path, failures
