"""The varied-task benchmark's episodes as arrays, split so nothing is measured where it was fitted.

Held-out in-range normal episodes split three ways: `precision` (each method's error spreads
and precision matrices, the time-varying threshold's step scales), `calibration` (the conformal
thresholds) and `test` (measured false alarms). Benign out-of-range normals and the faults are
only ever scored. Faults pair with their no-fault twins by seed; a fault's `onset` is the first
step at which it departs from its twin, and it is `visible` when some channel at or after the
onset departs by more than 3 normal standard deviations (per skill, step and channel, on the
precision split).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from models.sequences import Sequences
from pipelines.episodes import as_sequences
from runtime.parallel import Backend
from sim.episode import Episode
from sim.varied import channel_names, context_columns
from sim.varied_sets import VARIED_KINDS, generate

VISIBLE_K = 3.0
SPLIT = (150, 300)  # precision, calibration; the rest of the normal set is the test split


@dataclass(frozen=True)
class VariedBenchmark:
    context: str
    channel_names: tuple[str, ...]
    context_channels: np.ndarray  # indices of the perceived cube, goal and post channels
    demos: Sequences
    precision: Sequences
    calibration: Sequences
    test: Sequences
    ood: Sequences
    faults: Sequences
    twins: Sequences
    kinds: np.ndarray  # (F,) fault family
    fault_step: np.ndarray  # (F,) nominal start step of the fault
    onset: np.ndarray  # (F,) first step departing from the twin
    visible: np.ndarray  # (F,) bool
    dropped: dict  # set -> episodes the simulation refused (velocity limits, IK)


def ensure_varied_sets(data_dir: Path, workers: int, backend: Backend = "processes") -> tuple[dict, dict]:
    """Load the varied sets from data_dir, simulating missing ones; returns sets and drop counts."""
    from sim.dataset import load_episodes
    from sim.varied_sets import jobs_for

    sets, dropped = {}, {}
    for kind in VARIED_KINDS:
        path = data_dir / f"{kind}.mcap"
        if not path.exists():
            generate(kind, data_dir, workers, backend)
        sets[kind] = load_episodes(path)
        # a demos file may hold any number per skill (nasm demos --n-demos): its seeds say how many
        sizes = {"n_demos": 1 + max(e.seed for e in sets[kind])} if kind == "demos" else {}
        dropped[kind] = len(jobs_for(kind, **sizes)) - len(sets[kind])
    return sets, dropped


def make_benchmark(sets: dict[str, list[Episode]], context: str, dropped: dict | None = None,
                   split: tuple[int, int] = SPLIT) -> VariedBenchmark:
    names = tuple(sets["demos"][0].channel_names)
    columns = context_columns(names, context)
    kept = channel_names(context)
    twins = {e.seed: e for e in sets["twins"]}
    faults = [e for e in sets["faults"] if e.seed in twins]
    fault_arr = as_sequences(faults, columns)
    twin_arr = as_sequences([twins[e.seed] for e in faults], columns)
    normal = as_sequences(sets["normal"], columns)
    n_precision, n_calibration = split
    if len(normal) < n_precision + n_calibration + 10:
        raise ValueError(f"need at least {n_precision + n_calibration + 10} normal episodes, got {len(normal)}")
    index = np.arange(len(normal))
    precision = normal.take(index[:n_precision])
    onset, visible = departures(fault_arr, twin_arr, precision)
    ctx_names = [n for n in kept if n.startswith(("cube_seen", "goal", "post"))]
    return VariedBenchmark(
        context=context, channel_names=kept, context_channels=np.array([kept.index(n) for n in ctx_names]),
        demos=as_sequences(sets["demos"], columns), precision=precision,
        calibration=normal.take(index[n_precision:n_precision + n_calibration]),
        test=normal.take(index[n_precision + n_calibration:]), ood=as_sequences(sets["ood"], columns),
        faults=fault_arr, twins=twin_arr, kinds=np.array([e.fault.kind for e in faults]),
        fault_step=np.array([e.fault.step for e in faults]), onset=onset, visible=visible, dropped=dict(dropped or {}))


def departures(faults: Sequences, twins: Sequences, normal: Sequences) -> tuple[np.ndarray, np.ndarray]:
    """Each fault's first step departing from its twin, and whether it ever departs by more
    than VISIBLE_K normal standard deviations (per skill, step, channel) from then on."""
    diff = np.abs(faults.data - twins.data)
    moved = diff.max(axis=2) > 1e-6
    onset = np.where(moved.any(axis=1), moved.argmax(axis=1), faults.data.shape[1] - 1)
    sigma = np.ones_like(faults.data)
    for skill in np.unique(faults.labels):
        sigma[faults.labels == skill] = np.maximum(normal.data[normal.labels == skill].std(axis=0), 1e-6)
    steps = np.arange(diff.shape[1])
    after = np.where((steps[None] >= onset[:, None])[..., None], diff / sigma, 0.0)
    return onset, after.max(axis=(1, 2)) > VISIBLE_K


def load_varied_benchmark(data_dir: Path, context: str, workers: int = 2,
                          backend: Backend = "processes") -> VariedBenchmark:
    sets, dropped = ensure_varied_sets(Path(data_dir), workers, backend)
    return make_benchmark(sets, context, dropped)
