"""The default Panda model: trained on the simulated demonstrations, calibrated on
held-out normal episodes, written as a checkpoint the service can host.

The precision split of the held-out normal episodes (``pipelines.episodes``)
chooses the training epoch kept and gives the error spreads; the calibration split gives
the thresholds; the test split is left for measuring false-positive rates. Both recall
modes are calibrated, cued from one observation.
"""

from __future__ import annotations

from pathlib import Path

from neural_asm.models import checkpoint
from neural_asm.models.asm import NeuralASM
from neural_asm.models.config import FAST, RATE_DEFAULTS, SCORING, TPCConfig
from neural_asm.models.sequences import Sequences
from neural_asm.pipelines.episodes import NormalSets, load_normal_sets
from neural_asm.runtime.home import home_path
from neural_asm.sim.config import SIM
from neural_asm.sim.dataset import set_folder

DEFAULT_NAME = "panda"
CALIBRATION_SOURCE = "held-out normal episodes (simulated Panda)"


def train_calibrated(
    demos: Sequences,
    precision: Sequences,
    calibration: Sequences,
    channel_names: tuple[str, ...],
    config: TPCConfig = FAST,
    progress: bool = True,
    provenance: dict | None = None,
) -> NeuralASM:
    model = NeuralASM.fit(demos.data, channel_names, config, progress=progress, validation=precision.data,
                          labels=demos.labels, rate_hz=demos.rate_hz).noted(provenance or {})
    return calibrated(model, precision, calibration)


def calibrated(model: NeuralASM, precision: Sequences, calibration: Sequences) -> NeuralASM:
    """`model` calibrated in both recall modes, cued from one observation: spreads (and each
    skill's mean errors, where its rate centres them) from `precision`, thresholds from `calibration`."""
    for mode in ("offline", "online"):
        model.calibrate(precision.data, calibration.data, mode, 1, source=CALIBRATION_SOURCE, labels=precision.labels)
    return model


def provenance_of(bench: NormalSets, data_dir: Path) -> dict:
    return {
        "source": "simulated Panda pick-and-place (sim/)",
        "data_dir": str(data_dir),
        "demo_seeds": bench.demos.seeds.tolist(),
        "skills": sorted(set(bench.demos.labels.tolist())),
        "precision_seeds": bench.precision.seeds.tolist(),
        "threshold_seeds": bench.calibration.seeds.tolist(),
    }


def model_name(rate: float = SIM.timing.observation_hz) -> str:
    """The default model's name at `rate`: `panda` at 2 Hz, `panda-40hz` at 40 Hz."""
    return DEFAULT_NAME if rate == SIM.timing.observation_hz else f"{DEFAULT_NAME}-{rate:g}hz"


def calibrated_as_now(model: NeuralASM) -> bool:
    """Whether every calibration weighs errors as this release does at the model's rate (a 40 Hz
    checkpoint calibrated before calibrations took each skill's mean error out does not)."""
    centred = SCORING.centres_errors(model.rate_hz)
    return all((c.error_mean is not None) == centred for c in model.calibrations.values())


def ensure_default_model(models_dir: Path, data_dir: Path | None = None, progress: bool = True,
                         rate: float = SIM.timing.observation_hz) -> Path:
    """Return models_dir/<model_name(rate)>.safetensors, simulating data observed at `rate` and
    training it (the rate's default network, `RATE_DEFAULTS`) if missing, recalibrating it if
    its calibrations are of an older rule."""
    path = Path(models_dir) / f"{model_name(rate)}.safetensors"
    existing = checkpoint.load(path) if path.exists() else None
    if existing is not None and calibrated_as_now(existing):
        return path
    data_dir = home_path(set_folder(rate)) if data_dir is None else Path(data_dir)
    bench = load_normal_sets(data_dir, rate=rate)
    if existing is not None:
        if progress:
            print(f"recalibrating {path} (its calibrations are of an older rule)", flush=True)
        return checkpoint.save(calibrated(existing, bench.precision, bench.calibration), path)
    model = train_calibrated(
        bench.demos, bench.precision, bench.calibration, bench.channel_names, RATE_DEFAULTS[rate],
        progress=progress, provenance=provenance_of(bench, data_dir),
    )
    return checkpoint.save(model, path)
