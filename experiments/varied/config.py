"""The configs of the varied-task experiments: the benchmark, its ablation, its ceiling and the
BPTT diagnostic, all on the same episode sets."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Literal

from neural_asm.experiments.options import Simulates, data_folder, option
from neural_asm.experiments.varied.data import SPLIT

# The paper's batch-1 training over 160 varied demonstrations costs ~3 s per epoch here: the
# benchmark caps the paper-configured network's epochs to stay within minutes.
PAPER_EPOCHS = 40


@dataclass(frozen=True)
class VariedSets(Simulates):
    """The varied task's episode sets in one context variant, simulated where missing."""

    context: Literal["observed", "hidden"] = option("observed", "whether the goal is an observed channel")
    data: Path | None = option(None, "episode sets, simulated when missing (default: data_varied in the data home)")
    split: tuple[int, int] = SPLIT  # held-out normals estimating precisions, calibrating; the rest test

    @property
    def data_dir(self) -> Path:
        return data_folder(self.data, "data_varied")

    @property
    def folder(self) -> str:
        return f"varied_{self.context}"


@dataclass(frozen=True)
class VariedConfig(VariedSets):
    """Four skills whose cube, goal, speed and obstacle vary, nine fault families, every rival."""

    fast_epochs: int | None = option(None, "override the featured network's epochs")
    paper_epochs: int = option(PAPER_EPOCHS, "epochs of the paper-configured network")
    diagnostics: bool = option(False, "also train the featured network's form by BPTT (a measurement beyond "
                               "the paper, docs/diagnostic_bptt.md) into the headline")


@dataclass(frozen=True)
class AblationConfig(VariedSets):
    """One Neural ASM per lever of experiments/varied/ablation.py's VARIANTS."""

    variants: tuple[str, ...] = option((), "only this variant (repeat for more; default: all)", flag="variant")
    epochs: int | None = option(None, "override every variant's epochs")
    trainings: int = option(3, "trainings per variant (seeds 0, 1, ...)", min=1)

    def __post_init__(self) -> None:
        from neural_asm.experiments.varied.ablation import VARIANTS

        unknown = sorted(set(self.variants) - set(VARIANTS))
        if unknown:
            raise ValueError(f"unknown ablation variant(s) {unknown}; known: {sorted(VARIANTS)}")


@dataclass(frozen=True)
class CeilingConfig(VariedSets):
    """Two oracles that know each episode's exact context (experiments/varied/ceiling.py)."""


@dataclass(frozen=True)
class DiagnosticConfig(VariedSets):
    """The default network trained by its Hebbian rule and by BPTT against the best linear predictor."""

    trainings: int = option(3, "trainings per learner (seeds 0, 1, ...)", min=1)
