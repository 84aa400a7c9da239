"""Where the command line finds sequences: the built-in synthetic skills, an .npz
file of arrays, an MCAP episode set written by ``nasm demos``, or, with a channel mapping, a
robot's ROS 2 bags or LeRobot dataset (``logs``)."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np

from neural_asm.models.sequences import Sequences
from neural_asm.models.synthetic import make_skills

SYNTHETIC = "synthetic"


def load_sequences(source: str, mapping: str | Path | None = None) -> Sequences:
    """``synthetic``, ``file.npz`` (arrays ``sequences``, ``channel_names``, optional
    ``skills``) or an episode set ``file.mcap`` from the simulator; given a ``mapping`` file,
    ROS 2 bags or a LeRobot dataset read through it."""
    if mapping is not None:
        from neural_asm.logs.sources import load_log_sequences  # the log readers are only needed for logs

        return load_log_sequences(source, mapping)
    if source == SYNTHETIC:
        s = make_skills()
        return replace(s, labels=np.array([f"skill{k}" for k in s.labels]))
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
        return Sequences(data, labels, names, provenance={"source": str(path)})
    if path.suffix == ".mcap":
        from neural_asm.pipelines.episodes import as_sequences  # the simulator is only needed for its files
        from neural_asm.sim.dataset import load_episodes

        episodes = load_episodes(path)
        if not episodes:
            raise ValueError(f"{path} holds no episodes")
        return as_sequences(episodes, provenance={"source": str(path)})
    raise ValueError(f"unsupported data file {path}: use .npz or .mcap")
