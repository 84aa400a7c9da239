"""Simulated Panda episodes written the way a real robot's logs are: ROS 2 bags (rosbag2 MCAP,
CDR messages from the standard ROS 2 message definitions) and LeRobot datasets, together with
the channel mappings that read them back.

Bags are written with ``rosbags`` in any of the three storages a lab meets: ROS 2 MCAP, ROS 2
sqlite3 and ROS 1 ``.bag``. They carry the topics a Panda setup publishes, at rates of their own: ``/joint_states``
(sensor_msgs/msg/JointState, 40 Hz: the seven arm joints from the 40 Hz trace and the two
fingers), ``/ee_position`` (geometry_msgs/msg/PointStamped, 10 Hz), ``/gripper_closed``
(std_msgs/msg/Bool, 4 Hz), the finger-pad wrenches ``/left_pad/wrench`` and
``/right_pad/wrench`` (geometry_msgs/msg/WrenchStamped, 20 Hz) and a marker ``/episode``
(std_msgs/msg/String naming the skill) at each episode's start. Channels the simulator only
observes at 2 Hz are interpolated up to their topic's rate, and held over the settling block
after the last observation. ``jitter_s`` moves every stamp by up to that much, as a real
clock does.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any, Iterator

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import yaml
from rosbags.rosbag1 import Writer as Ros1Writer
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import Stores, get_typestore

from neural_asm.sim.channels import CHANNEL_NAMES, EE_CHANNELS, FINGER_CHANNELS, GRIPPER_CHANNEL, JOINT_NAMES, WRENCH_CHANNELS
from neural_asm.sim.config import SIM
from neural_asm.sim.episode import Episode

JOINT_STATE_NAMES = [f"panda_{j}" for j in JOINT_NAMES] + ["panda_finger_joint1", "panda_finger_joint2"]
RATES_HZ = {"/joint_states": 40.0, "/ee_position": 10.0, "/gripper_closed": 4.0,
            "/left_pad/wrench": 20.0, "/right_pad/wrench": 20.0}
TYPES = {"/joint_states": "sensor_msgs/msg/JointState", "/ee_position": "geometry_msgs/msg/PointStamped",
         "/gripper_closed": "std_msgs/msg/Bool", "/left_pad/wrench": "geometry_msgs/msg/WrenchStamped",
         "/right_pad/wrench": "geometry_msgs/msg/WrenchStamped", "/episode": "std_msgs/msg/String"}
WRENCH_FIELDS = ("force.x", "force.y", "force.z", "torque.x", "torque.y", "torque.z")
PAUSE_S = 3.0  # between episodes of one bag: longer than any split gap
START_NS = 1_700_000_000 * 10**9  # stamps of a recent date, as a real recording has
UNITS = {"joint": "rad", "ee": "m", "finger": "m", "gripper": "1", "force": "N", "torque": "N m"}
FPS = 10  # LeRobot frame rate: above the model's 2 Hz, so the reader resamples


def _units(name: str) -> str:
    if name.endswith(("_fx", "_fy", "_fz")):
        return UNITS["force"]
    if name.endswith(("_tx", "_ty", "_tz")):
        return UNITS["torque"]
    return UNITS[name.split("_")[0].rstrip("1234567")]


def _observed(ep: Episode, channels: slice | int, t: np.ndarray) -> np.ndarray:
    """2 Hz observations interpolated (held beyond the last) at times ``t``: (len(t), k)."""
    obs_t = SIM.timing.step_time(np.arange(len(ep.observations)))
    values = np.atleast_2d(ep.observations[:, channels].T).T
    return np.stack([np.interp(t, obs_t, values[:, j]) for j in range(values.shape[1])], axis=1)


def _times(hz: float) -> np.ndarray:
    return np.arange(round(SIM.timing.duration_s * hz) + 1) / hz


STORAGES = {"mcap": StoragePlugin.MCAP, "sqlite3": StoragePlugin.SQLITE3}
STORES = {"ros1": get_typestore(Stores.ROS1_NOETIC), "ros2": get_typestore(Stores.ROS2_HUMBLE)}


class BagWriter:
    """One bag being written with ``rosbags``: ``storage`` mcap or sqlite3 (a rosbag2 folder) or
    ros1 (a ``.bag`` file); ``definitions=False`` stores no message definitions (as ROS 2 Humble's
    sqlite3 bags), so readers must know the types themselves."""

    def __init__(self, path: Path, storage: str = "mcap", definitions: bool = True) -> None:
        self.ros1 = storage == "ros1"
        self.store = STORES["ros1" if self.ros1 else "ros2"]
        self.definitions = definitions
        path.parent.mkdir(parents=True, exist_ok=True)
        self.writer: Any = Ros1Writer(path) if self.ros1 else Writer(path, version=9, storage_plugin=STORAGES[storage])
        self.writer.open()
        self.connections: dict[str, Any] = {}

    def __enter__(self) -> "BagWriter":
        return self

    def __exit__(self, *exc: object) -> None:
        self.writer.close()

    def message(self, kind: str, **fields: Any) -> Any:
        return self.store.types[kind](**fields)

    def header(self, ns: int) -> Any:
        stamp = self.message("builtin_interfaces/msg/Time", sec=ns // 10**9, nanosec=ns % 10**9)
        extra = {"seq": 0} if self.ros1 else {}
        return self.message("std_msgs/msg/Header", stamp=stamp, frame_id="panda_link0", **extra)

    def write(self, topic: str, kind: str, ns: int, msg: Any) -> None:
        if topic not in self.connections:
            no_definition = {} if self.definitions or self.ros1 else {"msgdef": "", "rihs01": "RIHS01_" + "0" * 64}
            self.connections[topic] = self.writer.add_connection(topic, kind, typestore=self.store, **no_definition)
        raw = self.store.serialize_ros1(msg, kind) if self.ros1 else self.store.serialize_cdr(msg, kind)
        self.writer.write(self.connections[topic], ns, raw)


def _vector(w: BagWriter, values: Any) -> Any:
    x, y, z = (float(v) for v in values)
    return w.message("geometry_msgs/msg/Vector3", x=x, y=y, z=z)


def _body(w: BagWriter, topic: str, ns: int, body: dict[str, Any]) -> Any:
    """The message of one row of ``_messages``."""
    if topic == "/joint_states":
        return w.message(TYPES[topic], header=w.header(ns), name=body["name"], position=np.array(body["position"]),
                         velocity=np.zeros(0), effort=np.zeros(0))
    if topic == "/ee_position":
        point = w.message("geometry_msgs/msg/Point", x=float(body["xyz"][0]), y=float(body["xyz"][1]), z=float(body["xyz"][2]))
        return w.message(TYPES[topic], header=w.header(ns), point=point)
    if topic == "/gripper_closed":
        return w.message(TYPES[topic], data=body["data"])
    wrench = w.message("geometry_msgs/msg/Wrench", force=_vector(w, body["wrench"][:3]), torque=_vector(w, body["wrench"][3:]))
    return w.message(TYPES[topic], header=w.header(ns), wrench=wrench)


def _messages(ep: Episode) -> Iterator[tuple[str, float, dict[str, Any]]]:
    """(topic, time from the episode's start, fields) of one episode."""
    t = _times(RATES_HZ["/joint_states"])
    fingers = _observed(ep, FINGER_CHANNELS, t)
    arm = np.stack([np.interp(t, ep.t_hi, ep.qpos_hi[:, j]) for j in range(7)], axis=1)
    for k, tk in enumerate(t):
        yield "/joint_states", tk, {"name": JOINT_STATE_NAMES, "position": [*arm[k], *fingers[k]]}
    t = _times(RATES_HZ["/ee_position"])
    for tk, xyz in zip(t, _observed(ep, EE_CHANNELS, t)):
        yield "/ee_position", tk, {"xyz": xyz}
    t = _times(RATES_HZ["/gripper_closed"])
    steps = np.searchsorted(SIM.timing.step_time(np.arange(len(ep.observations))), t + 1e-9, side="right") - 1
    for tk, k in zip(t, steps):
        yield "/gripper_closed", tk, {"data": bool(ep.observations[k, GRIPPER_CHANNEL] > 0.5)}
    pads = ep.observations[:, WRENCH_CHANNELS]
    for side, cols in (("left", slice(0, 6)), ("right", slice(6, 12))):
        t = _times(RATES_HZ[f"/{side}_pad/wrench"])
        obs_t = SIM.timing.step_time(np.arange(len(pads)))
        w = np.stack([np.interp(t, obs_t, pads[:, cols][:, j]) for j in range(6)], axis=1)
        for tk, row in zip(t, w):
            yield f"/{side}_pad/wrench", tk, {"wrench": row}


def _write(writer: BagWriter, episodes: list[tuple[int, Episode]], rng: np.random.Generator, jitter_s: float,
           label: str | None = "/episode") -> None:
    for start_ns, ep in episodes:
        if label:
            writer.write(label, TYPES["/episode"], start_ns, writer.message(TYPES["/episode"], data=ep.skill))
        rows = sorted(_messages(ep), key=lambda m: m[1])
        noise = rng.uniform(-jitter_s, jitter_s, len(rows)) if jitter_s else np.zeros(len(rows))
        for (topic, t, body), dt in zip(rows, noise):
            ns = start_ns + int(round((max(t + dt, 0.0)) * 1e9))
            writer.write(topic, TYPES[topic], ns, _body(writer, topic, ns, body))


def bag_file(bag: Path) -> Path:
    """The one storage file of a bag written here (the .bag itself for ROS 1)."""
    return bag if bag.is_file() else next(p for p in sorted(bag.iterdir()) if p.suffix in (".mcap", ".db3"))


def write_bag(episodes: list[Episode], path: Path, jitter_s: float = 0.0, seed: int = 0, storage: str = "mcap",
              definitions: bool = True) -> Path:
    """All episodes in one bag, PAUSE_S apart, each opened by an ``/episode`` marker: a rosbag2
    folder at ``path`` (mcap, sqlite3) or a ROS 1 ``.bag`` file (ros1)."""
    period_ns = int((SIM.timing.duration_s + PAUSE_S) * 1e9)
    with BagWriter(path, storage, definitions) as writer:
        _write(writer, [(START_NS + i * period_ns, ep) for i, ep in enumerate(episodes)], np.random.default_rng(seed), jitter_s)
    return path


def write_bag_folders(episodes: list[Episode], folder: Path, jitter_s: float = 0.0, seed: int = 0,
                      storage: str = "mcap", label: str | None = "/episode") -> Path:
    """One rosbag2 folder per episode (``metadata.yaml`` + one storage file), as ``ros2 bag record`` leaves them."""
    rng = np.random.default_rng(seed)
    for i, ep in enumerate(episodes):
        with BagWriter(folder / f"episode_{i:04d}", storage) as writer:
            _write(writer, [(START_NS, ep)], rng, jitter_s, label)
    return folder


def bag_mapping(split: str = "marker", stamp: str = "header") -> dict[str, Any]:
    """The mapping of the bags above onto the simulator's 25 channels, as a mapping document."""
    channels: list[dict[str, Any]] = []
    for name, key in zip([*JOINT_NAMES, "finger_left", "finger_right"], JOINT_STATE_NAMES):
        channels.append({"name": name, "topic": "/joint_states", "field": "position", "key": key})
    channels += [{"name": f"ee_{a}", "topic": "/ee_position", "field": f"point.{a}"} for a in "xyz"]
    channels.sort(key=lambda c: CHANNEL_NAMES.index(c["name"]))
    channels.append({"name": "gripper_closed", "topic": "/gripper_closed", "field": "data", "interpolation": "previous"})
    for side in ("left", "right"):
        channels += [{"name": f"{side}_{f[0]}{f[-1]}", "topic": f"/{side}_pad/wrench", "field": f"wrench.{f}"}
                     for f in WRENCH_FIELDS]
    episodes = {"split": split, "label_topic": "/episode", "stamp": stamp}
    episodes |= {"marker_topic": "/episode"} if split == "marker" else {"gap_s": PAUSE_S / 2} if split == "gap" else {}
    return _document(channels, episodes)


def _document(channels: list[dict[str, Any]], episodes: dict[str, Any] | None) -> dict[str, Any]:
    for c in channels:
        c |= {"units": _units(c["name"]), "joint": c["name"] in JOINT_NAMES}
    assert [c["name"] for c in channels] == list(CHANNEL_NAMES)
    doc: dict[str, Any] = {"description": "simulated Panda, 25 channels",
                           "timing": {"period_s": 1 / SIM.timing.observation_hz, "steps": SIM.timing.n_steps,
                                      "max_gap_s": 0.3},
                           "channels": channels}
    return doc | ({"episodes": episodes} if episodes else {})


# --------------------------------------------------------------------------- LeRobot datasets

STATE_NAMES = [*JOINT_STATE_NAMES[:7], "finger_left", "finger_right"]
FEATURES = {
    "observation.state": {"dtype": "float32", "shape": [9], "names": STATE_NAMES},
    "observation.ee_pos": {"dtype": "float32", "shape": [3], "names": ["x", "y", "z"]},
    "observation.gripper": {"dtype": "float32", "shape": [1], "names": None},
    "observation.wrench": {"dtype": "float32", "shape": [12], "names": list(CHANNEL_NAMES[WRENCH_CHANNELS])},
    "timestamp": {"dtype": "float32", "shape": [1], "names": None},
    "frame_index": {"dtype": "int64", "shape": [1], "names": None},
    "episode_index": {"dtype": "int64", "shape": [1], "names": None},
    "index": {"dtype": "int64", "shape": [1], "names": None},
    "task_index": {"dtype": "int64", "shape": [1], "names": None},
}
V2_DATA_PATH = "data/chunk-{episode_chunk:03d}/episode_{episode_index:06d}.parquet"
V3_DATA_PATH = "data/chunk-{chunk_index:03d}/file-{file_index:03d}.parquet"


def _frames(ep: Episode, index: int, first: int, task: int) -> pa.Table:
    t = np.arange(round((len(ep.observations) - 1) / SIM.timing.observation_hz * FPS) + 1) / FPS
    arm = np.stack([np.interp(t, ep.t_hi, ep.qpos_hi[:, j]) for j in range(7)], axis=1)
    state = np.concatenate([arm, _observed(ep, FINGER_CHANNELS, t)], axis=1)

    def vectors(a: np.ndarray) -> pa.Array:
        return pa.FixedSizeListArray.from_arrays(pa.array(a.astype(np.float32).ravel()), a.shape[1])

    steps = np.searchsorted(SIM.timing.step_time(np.arange(len(ep.observations))), t + 1e-9, side="right") - 1
    n = len(t)
    return pa.table({
        "observation.state": vectors(state), "observation.ee_pos": vectors(_observed(ep, EE_CHANNELS, t)),
        "observation.gripper": pa.array(ep.observations[steps, GRIPPER_CHANNEL].astype(np.float32)),
        "observation.wrench": vectors(_observed(ep, WRENCH_CHANNELS, t)),
        "timestamp": pa.array(t.astype(np.float32)), "frame_index": pa.array(np.arange(n)),
        "episode_index": pa.array(np.full(n, index)), "index": pa.array(first + np.arange(n)),
        "task_index": pa.array(np.full(n, task)),
    })


def write_lerobot(episodes: list[Episode], root: Path, version: str = "v3.0") -> Path:
    """A LeRobot dataset of the episodes in the v2.1 or v3.0 on-disk layout (no videos)."""
    tasks = sorted({ep.skill for ep in episodes})
    tables, first = [], 0
    for i, ep in enumerate(episodes):
        tables.append(_frames(ep, i, first, tasks.index(ep.skill)))
        first += len(tables[-1])
    info: dict[str, Any] = {"codebase_version": version, "robot_type": "panda", "fps": FPS, "features": FEATURES,
                            "total_episodes": len(episodes), "total_frames": first, "total_tasks": len(tasks),
                            "chunks_size": 1000, "splits": {"train": f"0:{len(episodes)}"}, "video_path": None}
    (root / "meta").mkdir(parents=True, exist_ok=True)
    if version.startswith("v2"):
        info |= {"data_path": V2_DATA_PATH, "total_chunks": 1, "total_videos": 0}
        for i, table in enumerate(tables):
            path = root / V2_DATA_PATH.format(episode_chunk=0, episode_index=i)
            path.parent.mkdir(parents=True, exist_ok=True)
            pq.write_table(table, path)
        (root / "meta/tasks.jsonl").write_text("".join(json.dumps({"task_index": k, "task": s}) + "\n"
                                                       for k, s in enumerate(tasks)))
        (root / "meta/episodes.jsonl").write_text("".join(
            json.dumps({"episode_index": i, "tasks": [ep.skill], "length": len(t)}) + "\n"
            for i, (ep, t) in enumerate(zip(episodes, tables))))
    else:
        info |= {"data_path": V3_DATA_PATH, "data_files_size_in_mb": 100, "video_files_size_in_mb": 200}
        path = root / V3_DATA_PATH.format(chunk_index=0, file_index=0)
        path.parent.mkdir(parents=True, exist_ok=True)
        pq.write_table(pa.concat_tables(tables), path)
        pq.write_table(pa.table({"task_index": list(range(len(tasks))), "task": tasks}), root / "meta/tasks.parquet")
        ends = np.cumsum([len(t) for t in tables])
        meta = root / "meta/episodes/chunk-000/file-000.parquet"
        meta.parent.mkdir(parents=True, exist_ok=True)
        pq.write_table(pa.table({"episode_index": list(range(len(episodes))), "tasks": [[ep.skill] for ep in episodes],
                                 "length": [len(t) for t in tables], "data/chunk_index": [0] * len(episodes),
                                 "data/file_index": [0] * len(episodes),
                                 "dataset_from_index": (ends - [len(t) for t in tables]).tolist(),
                                 "dataset_to_index": ends.tolist()}), meta)
    (root / "meta/info.json").write_text(json.dumps(info, indent=2))
    return root


def lerobot_mapping() -> dict[str, Any]:
    """The mapping of the datasets above onto the simulator's 25 channels."""
    channels: list[dict[str, Any]] = [{"name": n, "feature": "observation.state", "key": k}
                                      for n, k in zip([*JOINT_NAMES, "finger_left", "finger_right"], STATE_NAMES)]
    channels += [{"name": f"ee_{a}", "feature": "observation.ee_pos", "index": i} for i, a in enumerate("xyz")]
    channels.sort(key=lambda c: CHANNEL_NAMES.index(c["name"]))
    channels.append({"name": "gripper_closed", "feature": "observation.gripper", "interpolation": "previous"})
    channels += [{"name": n, "feature": "observation.wrench", "key": n} for n in CHANNEL_NAMES[WRENCH_CHANNELS]]
    return _document(channels, None)


def write_mapping(doc: dict[str, Any], path: Path) -> Path:
    """A mapping document as a YAML file (the readers take TOML or YAML)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(yaml.safe_dump(doc, sort_keys=False))
    return path
