"""The monitors compared on the varied task, each reduced to what it expects of every step.

Every method works in the Neural ASM's normalised units and is scored by the same code
(experiments/varied/score.py). Baselines come from `models.detectors`: they may use each
episode's true skill label and the context channels of its first step (generous to them);
the Neural ASM is told neither: it recognises the skill and reads the context from the
observations it is cued with.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np
from tqdm.auto import tqdm

from experiments.varied.data import VariedBenchmark
from models.asm import NeuralASM
from models.config import TPCConfig
from models.detectors import all_detectors
from models.normaliser import Normaliser

Expect = Callable[[np.ndarray, np.ndarray], np.ndarray]


@dataclass(frozen=True)
class Method:
    name: str
    label: str
    is_neural_asm: bool
    expected: Expect  # normalised (N, T, D) and skills -> expectation (N, T, D)


def train_neural_asm(bench: VariedBenchmark, config: TPCConfig, progress: bool = True) -> NeuralASM:
    """A Neural ASM trained on the demonstrations, calibrated on the precision and calibration splits."""
    provenance = {"source": "simulated Panda, varied task (sim/varied.py)", "task": "varied",
                  "context": bench.context, "demo_seeds": bench.demos.seeds.tolist(),
                  "skills": sorted(set(bench.demos.labels.tolist()))}
    context = [bench.channel_names[i] for i in bench.context_channels]
    model = NeuralASM.fit(bench.demos.data, bench.channel_names, config, progress=progress, provenance=provenance,
                          validation=bench.precision.data, labels=bench.demos.labels, context_channels=context)
    for mode in ("offline", "online"):
        model.calibrate(bench.precision.data, bench.calibration.data, mode, 1,
                        source="held-out normal episodes of the varied task (simulated Panda)")
    return model


def neural_asm_methods(model: NeuralASM, name: str, label: str) -> list[Method]:
    def expect(mode: str) -> Expect:
        return lambda x, _skills: x - model.errors(model.normaliser.denormalise(x), mode, 1)

    return [Method(f"{name}_{mode}", f"{label}, {mode} recall", True, expect(mode)) for mode in ("offline", "online")]


def baseline_methods(bench: VariedBenchmark, norm: Normaliser, seed: int = 0) -> list[Method]:
    demos = norm.normalise(bench.demos.data)
    methods = []
    for detector in tqdm(all_detectors(), desc="fitting baselines"):
        detector.fit(demos, bench.demos.labels, bench.context_channels.tolist(), seed=seed)
        methods.append(Method(detector.name, detector.label, False, detector.expected))
    return methods
