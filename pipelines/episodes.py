"""Simulated episode sets as ``Sequences``, and the three-way split of held-out normals.

Held-out normal episodes are split three ways, so that no number is measured on the
episodes it was fitted to: precisions (each method's expected error spread, and the
training epoch kept), thresholds (energy percentiles), and a test split for the measured
false-positive rates.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from models.sequences import Sequences
from runtime.parallel import Backend
from sim.dataset import generate, load_episodes
from sim.episode import Episode

MIN_HELD_OUT = 60


def as_sequences(episodes: list[Episode], columns: np.ndarray | None = None,
                 provenance: dict | None = None) -> Sequences:
    """The episodes' observations (all channels, or ``columns``), skills and seeds."""
    if not episodes:
        raise ValueError("no episodes")
    names = tuple(episodes[0].channel_names)
    data = np.stack([e.observations for e in episodes])
    if columns is not None:
        data, names = data[:, :, columns], tuple(names[c] for c in columns)
    return Sequences(data, np.array([e.skill for e in episodes]), names,
                     seeds=np.array([e.seed for e in episodes]), provenance=provenance or {})


@dataclass(frozen=True)
class NormalSets:
    channel_names: tuple[str, ...]
    demos: Sequences
    precision: Sequences  # normal episodes for error spreads
    calibration: Sequences  # normal episodes for thresholds
    normal_test: Sequences  # normal episodes for measured false-positive rates


def split_normal(demos: list[Episode], normal_episodes: list[Episode]) -> NormalSets:
    normal = as_sequences(normal_episodes)
    n = len(normal)
    if n < MIN_HELD_OUT:
        raise ValueError(f"need at least {MIN_HELD_OUT} held-out normal episodes, got {n}")
    parts = np.array_split(np.arange(n), [n // 4, n // 4 + (3 * n) // 8])
    return NormalSets(normal.channel_names, as_sequences(demos), *(normal.take(p) for p in parts))


def ensure_sets(data_dir: Path, kinds: tuple[str, ...], n_normal: int, workers: int,
                backend: Backend = "processes") -> dict[str, list[Episode]]:
    """Load the sets from data_dir, simulating the missing ones."""
    out = {}
    for kind in kinds:
        path = data_dir / f"{kind}.mcap"
        if not path.exists():
            generate(kind, data_dir, workers=workers, n_normal=n_normal, backend=backend)
        out[kind] = load_episodes(path)
    return out


def load_normal_sets(data_dir: Path, n_normal: int = 400, workers: int = 2) -> NormalSets:
    sets = ensure_sets(data_dir, ("demos", "normal"), n_normal, workers)
    return split_normal(sets["demos"], sets["normal"])
