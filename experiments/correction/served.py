"""The monitor the service hosts for compliant control, beside the default model.

The default model is calibrated on episodes of the stiff servos. A compliant arm lags its plan
by load / K (the carried cube): every undisturbed compliant run exceeds that calibration's
threshold, so its flag would say nothing about a hit. The compliant monitor is the same
network calibrated the correction experiment's way, on undisturbed compliant executions of
recalled plans, for both recall modes and every rate, written as `<default>-compliant`, a
checkpoint the service hosts and a session names. It records the digest of the checkpoint
it was derived from and is rebuilt when that changes; being derived, it is never the
service's default (`service.registry`).
"""

from __future__ import annotations

from pathlib import Path

from experiments.correction.config import CORRECTION, CorrectionConfig
from experiments.correction.pipeline import undisturbed
from models import checkpoint
from models.recall import RECALL_MODES
from pipelines.default_model import DEFAULT_NAME, ensure_default_model

CONTROLLER = "compliant"
COMPLIANT_NAME = f"{DEFAULT_NAME}-{CONTROLLER}"


def digest_of(path: Path) -> str:
    """The tensor digest in a checkpoint's header (what the service's /models lists)."""
    return str(checkpoint.read_header(path.read_bytes(), str(path))["tensor_sha256"])


def ensure_compliant_model(models_dir: Path, config: CorrectionConfig = CORRECTION, progress: bool = True) -> Path:
    """Return models_dir/panda-compliant.safetensors, building the default model first if missing
    and (re)calibrating when it is missing or was derived from another default."""
    base = ensure_default_model(models_dir, progress=progress)
    path = base.with_name(f"{COMPLIANT_NAME}.safetensors")
    source = digest_of(base)
    if path.exists() and checkpoint.load(path).provenance.get("derived_from_sha256") == source:
        return path
    if progress:
        print(f"calibrating the monitor for compliant control ({2 * config.served_monitor_seeds} undisturbed "
              f"runs) into {path}", flush=True)
    model = checkpoint.load(base)
    precision, thresholds = undisturbed(model, config.with_(monitor_seeds=config.served_monitor_seeds), CONTROLLER)
    model.calibrations.clear()
    for mode in RECALL_MODES:
        model.calibrate(precision, thresholds, mode, 1, source=f"undisturbed recalled plans, {CONTROLLER} control")
    first = config.monitor_seed
    model.provenance |= {"derived_from": base.stem, "derived_from_sha256": source, "controller": CONTROLLER,
                         "monitor_seeds": [first, first + 2 * config.served_monitor_seeds - 1]}
    checkpoint.save(model, path)
    return path
