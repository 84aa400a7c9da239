"""The default Panda model: trained on the simulated demonstrations, calibrated on
held-out normal episodes, written as a checkpoint the service can host.

The precision split of the held-out normal episodes (``pipelines.episodes``)
chooses the training epoch kept and gives the error spreads; the calibration split gives
the thresholds; the test split is left for measuring false-positive rates. Both recall
modes are calibrated, cued from one observation.
"""

from __future__ import annotations

from pathlib import Path

from models import checkpoint
from models.asm import NeuralASM
from models.config import FAST, TPCConfig
from models.sequences import Sequences
from pipelines.episodes import NormalSets, load_normal_sets
from runtime.home import home_path

DEFAULT_NAME = "panda"


def train_calibrated(
    demos: Sequences,
    precision: Sequences,
    calibration: Sequences,
    channel_names: tuple[str, ...],
    config: TPCConfig = FAST,
    progress: bool = True,
    provenance: dict | None = None,
) -> NeuralASM:
    model = NeuralASM.fit(demos.data, channel_names, config, progress=progress, provenance=provenance,
                          validation=precision.data, labels=demos.labels)
    for mode in ("offline", "online"):
        model.calibrate(precision.data, calibration.data, mode, 1, source="held-out normal episodes (simulated Panda)")
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


def ensure_default_model(models_dir: Path, data_dir: Path | None = None, progress: bool = True) -> Path:
    """Return models_dir/panda.safetensors, simulating data and training it if missing."""
    path = Path(models_dir) / f"{DEFAULT_NAME}.safetensors"
    if path.exists():
        return path
    data_dir = home_path("data") if data_dir is None else Path(data_dir)
    bench = load_normal_sets(data_dir)
    model = train_calibrated(
        bench.demos, bench.precision, bench.calibration, bench.channel_names,
        progress=progress, provenance=provenance_of(bench, data_dir),
    )
    return checkpoint.save(model, path)
