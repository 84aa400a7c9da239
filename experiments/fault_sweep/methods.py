"""The detectors compared on the benchmark, each reduced to what it expects of every step.

All work in the Neural ASM's normalised units (z-scored with demonstration statistics),
so errors, energies and thresholds are computed the same way for every method. Each
``expected(x, skills)`` maps normalised sequences (N, T, D) and their true skill labels
to expectations (N, T, D); only the per-skill z-score is allowed to use the labels.
"""

from __future__ import annotations

import numpy as np

from neural_asm.experiments.methods import Expect, Method
from neural_asm.models.baselines import LinearOneStep, StepStatistics


def baseline_methods(demos: np.ndarray, skills: np.ndarray) -> list[Method]:
    """z-scores pooled over skills (the paper's baseline) and per true skill; the classic
    ASM (skill selected by the nearest first observation, then that skill's per-step
    statistics); a linear one-step predictor."""
    pooled = StepStatistics.fit(demos)
    names = np.unique(skills)
    library = StepStatistics.fit(demos, np.searchsorted(names, skills))
    linear = LinearOneStep.fit(demos)

    def by_label(table: np.ndarray) -> Expect:
        return lambda x, s: table[np.searchsorted(names, s)][:, : x.shape[1]]

    return [
        Method("zscore_pooled", "z-score, pooled over skills", False, lambda x, _s: pooled.expected(x),
               lambda x, _s: pooled.spread(x)),
        Method("zscore_per_skill", "z-score per true skill", False, by_label(library.means), by_label(library.stds)),
        Method("classic_asm", "classic ASM", False, lambda x, _s: library.expected(x), lambda x, _s: library.spread(x)),
        Method("linear_one_step", "linear one-step predictor", False, lambda x, _s: linear.expected(x)),
    ]
