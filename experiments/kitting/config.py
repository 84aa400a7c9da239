"""The kitting benchmark's one configuration: the split, the clock, the trainings, the windows."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from neural_asm.models.config import FAST, TPCConfig

# A smaller, shorter-trained default network: the 2-core budget of 20 minutes holds three trainings
# of the one network, of the per-skill networks and of the LSTM (the default H = 256 costs ~1.4 s
# an epoch on these 120-step segments here, H = 64 ~0.26 s).
# Its plan memory (fitted after training, the network unchanged) adds plan recall: the skill
# recognised at the cue, one of the benchmark's rows.
KITTING_NETWORK = FAST.with_(hidden_size=64, epochs=150, plan_memory=True)


@dataclass(frozen=True)
class KittingConfig:
    data: Path  # the clone's "No.0 filtering scheme" folder
    out: Path
    network: TPCConfig = KITTING_NETWORK
    trainings: int = 3  # seeds 0..trainings-1 of every learned method
    split_seed: int = 0
    train_fraction: float = 0.6  # of the runs (date stamps); the rest halved: calibration, test
    deltas_s: tuple[float, ...] = (0.0, 0.25, 0.5, 1.0)
    headline_delta_s: float = 0.5
    headline_skills: tuple[str, ...] = ("3", "4", "5")
    few_skills: tuple[str, ...] = ("7", "8", "9")
    fprs: tuple[float, ...] = (0.01, 0.05)
    recall_mode: str = "offline"  # the service's default
    lstm_epochs: int = 150
    not_anomalies: tuple[str, ...] = ("false_positive",)  # labelled by the dataset's authors as no anomaly
    whole_runs: bool = True

    @property
    def seeds(self) -> tuple[int, ...]:
        return tuple(range(self.trainings))
