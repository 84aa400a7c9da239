"""Where the command line finds sequences: the built-in synthetic skills, an .npz
file of arrays, an MCAP episode set written by ``nasm demos``, or, with a channel mapping, a
robot's ROS 2 bags or LeRobot dataset (``logs``)."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from models.synthetic import make_skills

SYNTHETIC = "synthetic"


@dataclass(frozen=True)
class Sequences:
    data: np.ndarray  # (N, T, D), original units
    channel_names: tuple[str, ...]
    labels: np.ndarray  # (N,) skill name of each sequence
    provenance: dict[str, Any] = field(default_factory=dict)


def load_sequences(source: str, mapping: str | Path | None = None) -> Sequences:
    """``synthetic``, ``file.npz`` (arrays ``sequences``, ``channel_names``, optional
    ``skills``) or an episode set ``file.mcap`` from the simulator; given a ``mapping`` file,
    ROS 2 bags or a LeRobot dataset read through it."""
    if mapping is not None:
        from logs.sources import load_log_sequences  # the log readers are only needed for logs

        return load_log_sequences(source, mapping)
    if source == SYNTHETIC:
        s = make_skills()
        labels = np.array([f"skill{k}" for k in s.skills])
        return Sequences(s.sequences, s.channel_names, labels, {"source": "synthetic", "seed": 0})
    path = Path(source)
    if not path.exists():
        raise FileNotFoundError(f"no data at {path} (expected '{SYNTHETIC}', an .npz or an .mcap file)")
    if path.suffix == ".npz":
        with np.load(path, allow_pickle=False) as f:
            if "sequences" not in f or "channel_names" not in f:
                raise ValueError(f"{path} needs arrays 'sequences' (N, T, D) and 'channel_names' (D,)")
            data = f["sequences"]
            labels = f["skills"].astype(str) if "skills" in f else np.full(len(data), "unknown")
            names = tuple(str(n) for n in f["channel_names"])
        return Sequences(data, names, labels, {"source": str(path)})
    if path.suffix == ".mcap":
        from sim.dataset import load_episodes  # the simulator is only needed for its files

        episodes = load_episodes(path)
        if not episodes:
            raise ValueError(f"{path} holds no episodes")
        return Sequences(
            np.stack([e.observations for e in episodes]),
            tuple(episodes[0].channel_names),
            np.array([e.skill for e in episodes]),
            {"source": str(path), "seeds": [int(e.seed) for e in episodes]},
        )
    raise ValueError(f"unsupported data file {path}: use .npz or .mcap")
