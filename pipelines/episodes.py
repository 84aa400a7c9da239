"""Simulated episode sets as ``Sequences``, and the three-way split of held-out normals.

Held-out normal episodes are split three ways, so that no number is measured on the
episodes it was fitted to: precisions (each method's expected error spread, and the
training epoch kept), thresholds (energy percentiles), and a test split for the measured
false-positive rates.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np

from neural_asm.models.sequences import Sequences
from neural_asm.runtime.parallel import Parallel
from neural_asm.sim.config import SIM
from neural_asm.sim.dataset import generate, load_episodes, set_folder
from neural_asm.sim.paper import PaperTask
from neural_asm.sim.runner import run_jobs
from neural_asm.sim.task import SetSizes
from neural_asm.sim.episode import Episode

MIN_HELD_OUT = 60
DEFAULT_N_NORMAL = 400  # held-out normal episodes simulated when none is asked for


class SetMismatch(ValueError):
    """An episode set already in the data folder is not the one asked for (another rate, another
    size): simulating over it would silently change earlier results, using it would silently
    measure something else."""


def as_sequences(episodes: list[Episode], columns: np.ndarray | None = None,
                 provenance: dict | None = None) -> Sequences:
    """The episodes' observations (all channels, or ``columns``), skills, seeds and rate."""
    if not episodes:
        raise ValueError("no episodes")
    rates = {e.rate_hz for e in episodes}
    if len(rates) != 1:
        raise ValueError(f"episodes observed at different rates {sorted(rates)} Hz cannot form one set of sequences")
    names = tuple(episodes[0].channel_names)
    data = np.stack([e.observations for e in episodes])
    if columns is not None:
        data, names = data[:, :, columns], tuple(names[c] for c in columns)
    return Sequences(data, np.array([e.skill for e in episodes]), names,
                     seeds=np.array([e.seed for e in episodes]), provenance=provenance or {}, rate_hz=rates.pop())


def simulated_episodes(kind: str = "demos", n_demos: int = 10, n_normal: int = 200,
                       rate_hz: float = SIM.timing.observation_hz, workers: int = 2) -> list[Episode]:
    """Simulate one of the paper task's episode sets (``neural_asm.sim.paper.KINDS``: ``demos``, ``normal``,
    ``faults``...); the episodes MuJoCo could not run are left out with a warning."""
    task = PaperTask(rate_hz)
    episodes, dropped = run_jobs(task, task.jobs(kind, SetSizes(n_demos, n_normal)), workers, desc=kind)
    for message in dropped:
        warnings.warn(f"left out: {message}", stacklevel=2)
    return episodes


def simulate_sequences(kind: str = "demos", n_demos: int = 10, n_normal: int = 200,
                       rate_hz: float = SIM.timing.observation_hz, workers: int = 2) -> Sequences:
    """``simulated_episodes`` as ``Sequences``: observations, skills, seeds and rate."""
    return as_sequences(simulated_episodes(kind, n_demos, n_normal, rate_hz, workers), provenance={"simulated": kind})


@dataclass(frozen=True)
class NormalSets:
    channel_names: tuple[str, ...]
    demos: Sequences
    precision: Sequences  # normal episodes for error spreads
    calibration: Sequences  # normal episodes for thresholds
    normal_test: Sequences  # normal episodes for measured false-positive rates


def split_three(normal: Sequences, n_precision: int, n_calibration: int) -> tuple[Sequences, Sequences, Sequences]:
    """Held-out normals in order: precisions, thresholds, and the rest for measured false alarms."""
    if n_precision < 1 or n_calibration < 1 or len(normal) < n_precision + n_calibration + 10:
        raise ValueError(f"need at least {n_precision + n_calibration + 10} held-out normal episodes "
                         f"({n_precision} precision, {n_calibration} calibration, 10 test), got {len(normal)}")
    index = np.arange(len(normal))
    return (normal.take(index[:n_precision]), normal.take(index[n_precision:n_precision + n_calibration]),
            normal.take(index[n_precision + n_calibration:]))


def split_normal(demos: list[Episode], normal_episodes: list[Episode]) -> NormalSets:
    """The paper benchmark's split: a quarter for precisions, three eighths for thresholds."""
    normal = as_sequences(normal_episodes)
    n = len(normal)
    if n < MIN_HELD_OUT:
        raise ValueError(f"need at least {MIN_HELD_OUT} held-out normal episodes, got {n}")
    return NormalSets(normal.channel_names, as_sequences(demos), *split_three(normal, n // 4, (3 * n) // 8))


Simulate = Callable[[str, Path], object]  # (set kind, folder) -> writes <folder>/<kind>.mcap


def ensure_sets(data_dir: Path, kinds: tuple[str, ...], simulate: Simulate) -> dict[str, list[Episode]]:
    """Load the sets from data_dir, simulating the missing ones."""
    out = {}
    for kind in kinds:
        path = Path(data_dir) / f"{kind}.mcap"
        if not path.exists():
            simulate(kind, Path(data_dir))
        out[kind] = load_episodes(path)
    return out


def paper_sets(data_dir: Path, kinds: tuple[str, ...], n_normal: int | None = None,
               parallel: Parallel = Parallel(), rate: float = SIM.timing.observation_hz) -> dict[str, list[Episode]]:
    """The paper task's sets (sim/paper.py) observed at `rate`, simulated where missing
    (`n_normal` held-out normal episodes, `DEFAULT_N_NORMAL` when None). The sets already there
    are checked before anything is simulated: one at another rate is refused (a folder holds one
    rate: `sim.dataset.set_folder`), and so is a normal set of another size than an `n_normal`
    given."""
    folder = Path(data_dir)
    found = {kind: load_episodes(folder / f"{kind}.mcap") for kind in kinds if (folder / f"{kind}.mcap").exists()}
    for kind, episodes in found.items():
        if episodes and episodes[0].rate_hz != rate:
            raise SetMismatch(f"{folder / kind}.mcap holds episodes at {episodes[0].rate_hz:g} Hz, not {rate:g} Hz: "
                              f"use the folder {set_folder(rate)!r} of the data home for that rate")
    if n_normal is not None and "normal" in found and len(found["normal"]) != n_normal:
        raise SetMismatch(f"{folder / 'normal'}.mcap holds {len(found['normal'])} held-out normal episodes, not the "
                          f"{n_normal} asked for: give another data folder (the other sets can be linked into it) "
                          f"or move that file away to simulate {n_normal}")
    missing = tuple(kind for kind in kinds if kind not in found)
    sizes = SetSizes(n_normal=n_normal or DEFAULT_N_NORMAL)
    sets = found | ensure_sets(folder, missing, lambda kind, into: generate(
        PaperTask(rate), kind, into, sizes, parallel.workers, parallel.backend))
    return {kind: sets[kind] for kind in kinds}


def load_normal_sets(data_dir: Path, n_normal: int | None = None, parallel: Parallel = Parallel(),
                     rate: float = SIM.timing.observation_hz) -> NormalSets:
    sets = paper_sets(data_dir, ("demos", "normal"), n_normal, parallel, rate)
    return split_normal(sets["demos"], sets["normal"])
