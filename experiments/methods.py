"""A monitor as every benchmark here compares it: reduced to what it expects of every step.

Methods work in the Neural ASM's normalised units (z-scored with demonstration statistics),
so errors, energies and thresholds are computed the same way for every one of them.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Callable

import numpy as np
from tqdm.auto import tqdm

from neural_asm.models.asm import NeuralASM
from neural_asm.rivals.base import Detector, Spread

Expect = Callable[[np.ndarray, np.ndarray], np.ndarray]  # normalised (N, T, D) and true skills -> (N, T, D)


@dataclass(frozen=True)
class Method:
    name: str
    label: str
    is_neural_asm: bool
    expected: Expect
    # z-score methods: the demonstrations' per-step std of the entry used (N, T, D), the
    # paper's own weighting. None for predictors.
    demo_spread: Expect | None = None

    @property
    def family(self) -> str:
        return "neural_asm" if self.is_neural_asm else "baseline"


def neural_asm_methods(model: NeuralASM, name: str, label: str) -> list[Method]:
    """The network in each of its recall modes; it is told neither the skill nor the context (plan recall
    recognises the skill from the cue)."""
    def expect(mode: str) -> Expect:
        return lambda x, _skills: x - model.errors(model.normaliser.denormalise(x), mode, 1)

    return [Method(f"{name}_{mode}", f"{label}, {mode} recall", True, expect(mode)) for mode in model.recall_modes]


def rival_methods(rivals: Sequence[Detector], demos: np.ndarray, skills: np.ndarray, context_channels: Sequence[int],
                  seed: int = 0) -> list[Method]:
    """Each rival fitted on the normalised demonstrations (told their skills and which channels
    are context), with its spread where it is a z-score."""
    methods = []
    for rival in tqdm(rivals, desc="fitting rivals"):
        rival.fit(demos, skills, context_channels, seed=seed)
        spread = rival.spread if isinstance(rival, Spread) else None
        methods.append(Method(rival.name, rival.label, False, rival.expected, spread))
    return methods
