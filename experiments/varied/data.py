"""The varied-task benchmark's episodes as arrays, split so nothing is measured where it was fitted.

Held-out in-range normal episodes split three ways: `precision` (each method's error spreads
and precision matrices, the time-varying threshold's step scales), `calibration` (the episode
thresholds) and `test` (measured false alarms). Benign out-of-range normals and the faults are
only ever scored. Faults pair with their no-fault twins by seed; a fault's `onset` is the first
step at which it departs from its twin, and it is `visible` when some channel at or after the
onset departs by more than 3 normal standard deviations (per skill, step and channel, on the
precision split; `experiments.twins`).

The validation faults (`validation`: other seeds, the same families and skills, a quarter as
many) get their onset and visibility by the same rule. They serve choices that need faults, the
either-of-two rival's pair (experiments/varied/pairs.py), and nothing else: no method is fitted,
calibrated or thresholded on them, and no rate is measured on them.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from neural_asm.experiments.twins import consequences, onset_steps, visible_from, whitened_deviation
from neural_asm.models.sequences import Sequences
from neural_asm.pipelines.episodes import as_sequences, ensure_sets, split_three
from neural_asm.runtime.parallel import Parallel
from neural_asm.sim.episode import Episode
from neural_asm.sim.varied import channel_names, check_context, context_columns
from neural_asm.sim.dataset import generate
from neural_asm.sim.task import SetSizes
from neural_asm.sim.varied_sets import VARIED, VARIED_KINDS, jobs_for

if TYPE_CHECKING:
    from neural_asm.experiments.varied.config import VariedSets

SPLIT = (150, 300)  # precision, calibration; the rest of the normal set is the test split


@dataclass(frozen=True)
class FaultSet:
    """Fault episodes paired with their no-fault twins, and what the pairing says of each."""

    faults: Sequences
    twins: Sequences
    kinds: np.ndarray  # (F,) fault family
    fault_step: np.ndarray  # (F,) nominal start step of the fault
    onset: np.ndarray  # (F,) first step departing from the twin
    visible: np.ndarray  # (F,) bool
    consequence: np.ndarray  # (F,) experiments.twins.CONSEQUENCES


def fault_set(faults: list[Episode], twins: list[Episode], columns: np.ndarray, precision: Sequences) -> FaultSet:
    """Faults that have a twin (the simulation may refuse either), their onset, visibility (in
    standard deviations of the precision split's normals) and consequence."""
    by_seed = {e.seed: e for e in twins}
    faults = [e for e in faults if e.seed in by_seed]
    twins = [by_seed[e.seed] for e in faults]
    fault_arr, twin_arr = as_sequences(faults, columns), as_sequences(twins, columns)
    onset = onset_steps(fault_arr.data, twin_arr.data)
    deviation = whitened_deviation(fault_arr.data, twin_arr.data, fault_arr.labels, precision.data, precision.labels)
    visible = visible_from(deviation, onset)
    consequence = consequences(np.array([e.success for e in faults]), np.array([e.success for e in twins]), visible)
    return FaultSet(fault_arr, twin_arr, np.array([e.fault.kind for e in faults]),
                    np.array([e.fault.step for e in faults]), onset, visible, consequence)


@dataclass(frozen=True)
class VariedBenchmark(FaultSet):
    """The test faults (the `FaultSet` it extends), the normal splits and the demonstrations."""

    context: str
    channel_names: tuple[str, ...]
    context_channels: np.ndarray  # indices of the perceived cube, goal and post channels
    demos: Sequences
    precision: Sequences
    calibration: Sequences
    test: Sequences
    ood: Sequences
    test_success: np.ndarray  # (N_test,) bool: the normal test episode placed its cube
    ood_success: np.ndarray  # (N_ood,) bool: the benign out-of-range run placed its cube
    dropped: dict  # set -> episodes the simulation refused (velocity limits, IK)
    validation: FaultSet | None = None  # validation faults: only for choices among rivals


def ensure_varied_sets(data_dir: Path, parallel: Parallel = Parallel()) -> tuple[dict, dict]:
    """Load the varied sets from data_dir, simulating missing ones; returns sets and drop counts."""
    sets = ensure_sets(data_dir, VARIED_KINDS, lambda kind, folder: generate(
        VARIED, kind, folder, SetSizes(), parallel.workers, parallel.backend))
    dropped = {}
    for kind, episodes in sets.items():
        # a demos file may hold any number per skill (nasm demos --n-demos): its seeds say how many
        sizes = SetSizes(n_demos=1 + max(e.seed for e in episodes)) if kind == "demos" else SetSizes()
        dropped[kind] = len(jobs_for(kind, sizes)) - len(episodes)
    return sets, dropped


def make_benchmark(sets: dict[str, list[Episode]], context: str, dropped: dict | None = None,
                   split: tuple[int, int] = SPLIT) -> VariedBenchmark:
    """The benchmark of the sets; without `val_faults` among them it has no validation faults."""
    names = tuple(sets["demos"][0].channel_names)
    columns = context_columns(names, context)
    kept = channel_names(context)
    normal = as_sequences(sets["normal"], columns)
    precision, calibration, test = split_three(normal, *split)
    test_faults = fault_set(sets["faults"], sets["twins"], columns, precision)
    validation = fault_set(sets["val_faults"], sets["val_twins"], columns, precision) if "val_faults" in sets else None
    ctx_names = [n for n in kept if n.startswith(("cube_seen", "goal", "post"))]
    return VariedBenchmark(
        **vars(test_faults), context=context, channel_names=kept,
        context_channels=np.array([kept.index(n) for n in ctx_names]),
        demos=as_sequences(sets["demos"], columns), precision=precision, calibration=calibration, test=test,
        ood=as_sequences(sets["ood"], columns),
        test_success=np.array([e.success for e in sets["normal"]])[len(precision) + len(calibration):],
        ood_success=np.array([e.success for e in sets["ood"]]), dropped=dict(dropped or {}), validation=validation)


def load_varied_benchmark(data_dir: Path, context: str, parallel: Parallel = Parallel(),
                          split: tuple[int, int] = SPLIT) -> VariedBenchmark:
    """The benchmark in one context variant, its episode sets simulated into `data_dir` where
    missing; an unknown context is refused before any simulation starts."""
    check_context(context)
    sets, dropped = ensure_varied_sets(Path(data_dir), parallel)
    return make_benchmark(sets, context, dropped, split)


def benchmark_of(config: VariedSets) -> VariedBenchmark:
    """The benchmark an experiment's config names."""
    return load_varied_benchmark(config.data_dir, config.context, config.parallel, config.split)
