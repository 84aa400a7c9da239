"""Where the command line finds sequences, and the one way every command that takes data reads
it (``read_data``): the built-in synthetic skills, an .npz file of arrays, an MCAP episode set
written by ``nasm demos``, or, with a channel mapping, a robot's logs in any registered format
(``logs.formats``: ROS bags, LeRobot datasets, a lab's tables)."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from neural_asm.logs.cli import FORMATS
from neural_asm.models.sequences import Sequences
from neural_asm.models.synthetic import make_skills

if TYPE_CHECKING:
    from neural_asm.models.asm import NeuralASM

SYNTHETIC = "synthetic"
DATA_HELP = f"'{SYNTHETIC}', an .npz of sequences, an .mcap episode set, or (with --mapping) {FORMATS}"


def read_training_data(provenance: dict) -> Sequences:
    """The demonstrations a checkpoint was trained on, read again where its provenance says they
    came from (logs through the mapping they were read with: `logs.sources.read_again`; else the
    source `load_sequences` recorded); a ValueError says why they cannot be."""
    from neural_asm.logs.sources import read_again

    source = provenance.get("source")
    if source is None:
        raise ValueError("the checkpoint does not record where its training data came from")
    try:
        logs = read_again(provenance)
        return load_sequences(source) if logs is None else logs
    except (OSError, ValueError) as exc:
        raise ValueError(f"its training data ({source}) cannot be read again: {exc}") from None


def load_sequences(source: str) -> Sequences:
    """``synthetic``, ``file.npz`` (arrays ``sequences``, ``channel_names``, optional
    ``skills``) or an episode set ``file.mcap`` from the simulator; a ValueError (or
    FileNotFoundError) names what is wrong."""
    if source == SYNTHETIC:
        s = make_skills()
        return replace(s, labels=np.array([f"skill{k}" for k in s.labels]))
    path = Path(source)
    if not path.exists():
        raise FileNotFoundError(f"no data at {path} (expected '{SYNTHETIC}', an .npz or an .mcap file; logs need "
                                "--mapping)")
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
    raise ValueError(f"unsupported data file {path}: use .npz or .mcap, or logs with --mapping")


def read_data(source: str, mapping: Path | None = None, skip_bad: bool = False,
              model: NeuralASM | None = None) -> Sequences:
    """The data of every command that takes some: logs through ``mapping`` (``logs.cli.read_logs``,
    its warnings printed), else ``load_sequences``; checked against ``model``'s channels (and for
    logs its mapping's units and clock) if given. Any problem ends the command in one line (exit 2)."""
    from neural_asm.logs.cli import read_logs
    from neural_asm.runtime.cli import fail

    if mapping is not None:
        return read_logs(source, mapping, model, skip_bad)
    if skip_bad:
        raise fail("--skip-bad skips bad episodes of logs: give --mapping")
    try:
        seqs = load_sequences(source)
    except (OSError, ValueError) as exc:
        raise fail(exc) from None
    if model is not None and tuple(seqs.channel_names) != model.channel_names:
        raise fail(f"{source} has channels {list(seqs.channel_names)}; the model expects {list(model.channel_names)}")
    return seqs
