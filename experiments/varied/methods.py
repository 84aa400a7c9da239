"""The monitors compared on the varied task, each reduced to what it expects of every step.

Every method works in the Neural ASM's normalised units and is scored by the same code
(experiments/varied/score.py). The rivals are `rivals.registry`'s varied line-up: they may use each
episode's true skill label and the context channels of its first step (generous to them);
the Neural ASM is told neither: it recognises the skill and reads the context from the
observations it is cued with.
"""

from __future__ import annotations

from neural_asm.experiments.methods import Method, rival_methods
from neural_asm.experiments.varied.data import VariedBenchmark
from neural_asm.models.asm import NeuralASM
from neural_asm.models.config import TPCConfig
from neural_asm.models.normaliser import Normaliser
from neural_asm.rivals.registry import line_up


def train_neural_asm(bench: VariedBenchmark, config: TPCConfig, progress: bool = True) -> NeuralASM:
    """A Neural ASM trained on the demonstrations, calibrated on the precision and calibration splits."""
    provenance = {"source": "simulated Panda, varied task (sim/varied.py)", "task": "varied",
                  "context": bench.context, "demo_seeds": bench.demos.seeds.tolist(),
                  "skills": sorted(set(bench.demos.labels.tolist()))}
    context = [bench.channel_names[i] for i in bench.context_channels]
    model = NeuralASM.fit(bench.demos.data, bench.channel_names, config, progress=progress,
                          validation=bench.precision.data, labels=bench.demos.labels,
                          context_channels=context).noted(provenance)
    for mode in model.recall_modes:
        model.calibrate(bench.precision.data, bench.calibration.data, mode, 1,
                        source="held-out normal episodes of the varied task (simulated Panda)")
    return model


def baseline_methods(bench: VariedBenchmark, norm: Normaliser, seed: int = 0) -> list[Method]:
    return rival_methods(line_up("varied"), norm.normalise(bench.demos.data), bench.demos.labels,
                         bench.context_channels.tolist(), seed)
