"""The episode sets of the fault benchmark: the normal split (``pipelines.episodes``) and
the faults paired with their no-fault twins by seed."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from neural_asm.models.sequences import Sequences
from neural_asm.pipelines.episodes import NormalSets, as_sequences, paper_sets, split_normal
from neural_asm.runtime.parallel import Parallel
from neural_asm.sim.episode import Episode

SETS = ("demos", "normal", "faults", "twins")


@dataclass(frozen=True)
class Benchmark:
    normal: NormalSets
    faults: Sequences
    twins: Sequences  # the faults' seeds without the fault
    fault_joint: np.ndarray  # (F,) 1..7
    fault_step: np.ndarray  # (F,) observation step of the overshoot
    fault_time: np.ndarray  # (F,) s
    overshoot: np.ndarray  # (F,) degrees


def make_benchmark(sets: dict[str, list[Episode]]) -> Benchmark:
    """Pair the sets of SETS into a benchmark (faults with their twins by seed)."""
    faults = sets["faults"]
    if [e.seed for e in faults] != [e.seed for e in sets["twins"]]:
        raise ValueError("fault and twin episodes do not pair up by seed")
    specs = [e.fault for e in faults]
    return Benchmark(
        normal=split_normal(sets["demos"], sets["normal"]),
        faults=as_sequences(faults),
        twins=as_sequences(sets["twins"]),
        fault_joint=np.array([s.joint for s in specs]),
        fault_step=np.array([s.step for s in specs]),
        fault_time=np.array([s.time_s for s in specs]),
        overshoot=np.array([s.overshoot_deg for s in specs]),
    )


def load_benchmark(data_dir: Path, n_normal: int | None = None, *, parallel: Parallel = Parallel()) -> Benchmark:
    return make_benchmark(paper_sets(data_dir, SETS, n_normal, parallel))
