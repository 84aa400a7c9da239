"""The configs of the paper task's sweeps: the paper's 2 Hz sweep and the served monitor at 40 Hz."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from neural_asm.experiments.options import Simulates, data_folder, option
from neural_asm.models.config import FAITHFUL
from neural_asm.sim.cli import RATE_HELP
from neural_asm.sim.config import SIM
from neural_asm.sim.dataset import set_folder


@dataclass(frozen=True)
class PaperSets(Simulates):
    """The paper task's episode sets (sim/paper.py), simulated where missing."""

    data: Path | None = option(None, "episode sets, simulated when missing (default: the data home's folder "
                               "of the rate: data, data_40hz)")
    n_normal: int | None = option(None, "held-out normal episodes: simulated when the data folder has none "
                                  "(default 400); a set already there must hold this many", min=60)

    def data_dir(self, rate: float = SIM.timing.observation_hz) -> Path:
        return data_folder(self.data, set_folder(rate))


@dataclass(frozen=True)
class PaperSweepConfig(PaperSets):
    """The 980 joint locks: the default and the paper-configured network against the baselines."""

    paper_epochs: int = option(FAITHFUL.epochs, "epochs of the paper-configuration model")
    fast_epochs: int | None = option(None, "override the default model's epochs")


@dataclass(frozen=True)
class RateConfig(PaperSets):
    """The served monitor at `rate` and at 2 Hz on the joint locks and the falling object, with latency."""

    rate: int = option(40, f"{RATE_HELP} The monitor's rate, scored beside the 2 Hz one")
    epochs: int | None = option(None, "override the `rate` network's epochs")
    trainings: int = option(3, "trainings per rate (seeds 0, 1, ...; the first is saved and headlines)", min=1)

    def __post_init__(self) -> None:
        SIM.timing.ticks_per_observation(self.rate)  # a ValueError for a rate episodes cannot be observed at
