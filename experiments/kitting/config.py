"""The kitting benchmark's one configuration (the split, the clock, the trainings, the windows) and
the options its command offers (`KittingRun`)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from neural_asm.experiments.options import Simulates, option
from neural_asm.logs.errors import LogError
from neural_asm.models.config import FAST, TPCConfig
from neural_asm.runtime.home import home_path
from neural_asm.runtime.parallel import Parallel

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
    splits: tuple[int, ...] = ()  # several run-wise splits' seeds, each run as ``split_seed`` (none: that one)
    train_fraction: float = 0.6  # of the runs (date stamps); the rest halved: calibration, test
    deltas_s: tuple[float, ...] = (0.0, 0.25, 0.5, 1.0)
    headline_delta_s: float = 0.5
    headline_skills: tuple[str, ...] = ("3", "4", "5")
    few_skills: tuple[str, ...] = ("7", "8", "9")
    fprs: tuple[float, ...] = (0.01, 0.05)
    threshold_folds: int = 5  # the cross-fitted threshold's folds of the training runs (`score_cross_fitted`)
    recall_mode: str = "offline"  # nasm_one's, the paper's mode (nasm_one_online: what a 20 Hz model is served in)
    lstm_epochs: int = 150
    not_anomalies: tuple[str, ...] = ("false_positive",)  # labelled by the dataset's authors as no anomaly
    whole_runs: bool = True
    parallel: Parallel = Parallel(1)  # where the splits run, each in one process


    @property
    def seeds(self) -> tuple[int, ...]:
        return tuple(range(self.trainings))

    @property
    def split_seeds(self) -> tuple[int, ...]:
        return self.splits or (self.split_seed,)


@dataclass(frozen=True)
class KittingRun(Simulates):
    """What `nasm experiments run kitting` (and `nasm faults --task kitting`) is given; the rest of
    the protocol is `KittingConfig`'s. The size is an option because docs/kitting.md measures a
    larger network than the default; the workers, because the splits run side by side."""

    data: Path | None = option(None, "the clone's 'anomaly_detection_feature_selection_folder/No.0 filtering "
                               "scheme' folder")
    trainings: int = option(3, "trainings of every learned method (seeds 0, 1, ...)", flag="seeds", min=1)
    hidden_size: int = option(KITTING_NETWORK.hidden_size, "hidden units of the one network and the per-skill "
                              "networks", min=1)
    epochs: int = option(KITTING_NETWORK.epochs, "their training epochs", min=1)
    split_seed: int = option(0, "the seed that shuffles the runs before they are split into train, calibration "
                             "and test (another split, the same protocol)", min=0)
    splits: tuple[int, ...] = option((), "several run-wise splits' seeds (the option repeated, or several values "
                                     "after it), each trained and scored in turn; the headline pools them and gives "
                                     "each in by_split (instead of one split seed)")
    # The command's --out: the run writes its model there, then serves it to the whole runs.
    out: Path | None = None

    def __post_init__(self) -> None:
        if self.splits and self.split_seed:
            raise ValueError("give --splits or --split-seed, not both")
        if any(k < 0 for k in self.splits) or len(set(self.splits)) != len(self.splits):
            raise ValueError(f"--splits: distinct seeds >= 0, got {list(self.splits)}")

    def config(self) -> KittingConfig:
        """The benchmark's configuration; a folder that is not the clone's is refused in one line."""
        if self.data is None or not (self.data / "successful_skills").is_dir():
            raise LogError(f"{self.data or 'no --data'}: no successful_skills folder: give the clone's "
                           "'anomaly_detection_feature_selection_folder/No.0 filtering scheme' folder")
        network = KITTING_NETWORK.with_(hidden_size=self.hidden_size, epochs=self.epochs)
        return KittingConfig(data=self.data, out=self.out or home_path("kitting"), trainings=self.trainings,
                             network=network, split_seed=self.split_seed, splits=tuple(self.splits),
                             parallel=self.parallel)
