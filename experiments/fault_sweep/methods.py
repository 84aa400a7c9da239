"""The detectors compared on the benchmark, each reduced to what it expects of every step.

All work in the Neural ASM's normalised units (z-scored with demonstration statistics),
so errors, energies and thresholds are computed the same way for every method. Each
``expected(x, skills)`` maps normalised sequences (N, T, D) and their true skill labels
to expectations (N, T, D); only the per-skill z-score is allowed to use the labels.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from models.asm import NeuralASM
from models.baselines import LinearOneStep, StepStatistics

Expect = Callable[[np.ndarray, np.ndarray], np.ndarray]


@dataclass(frozen=True)
class Method:
    name: str
    family: str  # "neural_asm" or "baseline"
    expected: Expect
    # z-score methods: the demonstrations' per-step std of the entry used, the paper's
    # own weighting (N, T, D). None for predictors.
    demo_spread: Expect | None = None


def neural_asm_methods(model: NeuralASM, label: str) -> list[Method]:
    def expect(mode: str) -> Expect:
        return lambda x, _skills: x - model.errors(model.normaliser.denormalise(x), mode, 1)

    return [Method(f"{label}_{mode}", "neural_asm", expect(mode)) for mode in ("offline", "online")]


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
        Method("zscore_pooled", "baseline", lambda x, _s: pooled.expected(x), lambda x, _s: pooled.spread(x)),
        Method("zscore_per_skill", "baseline", by_label(library.means), by_label(library.stds)),
        Method("classic_asm", "baseline", lambda x, _s: library.expected(x), lambda x, _s: library.spread(x)),
        Method("linear_one_step", "baseline", lambda x, _s: linear.expected(x)),
    ]
