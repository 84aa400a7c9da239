"""Fault detection on logged episodes, as ``nasm faults`` measures it on simulated ones, for
logs where only whole episodes are known to be normal or faulty: which episodes a checkpoint's
calibrated threshold flags, where first, which joint it blames, and how well episode peak
energies separate the two sets."""

from __future__ import annotations

from typing import Any

import numpy as np
from sklearn.metrics import roc_auc_score

from logs.errors import LogError
from models.asm import NeuralASM
from models.fault import isolate
from models.scoring import step_rows
from models.sequences import Sequences


def _flags(model: NeuralASM, seqs: Sequences, mode: str, threshold: float, error_std: np.ndarray) -> list[dict[str, Any]]:
    result = model.score(seqs.data, mode, 1, True)
    weighted = result.errors / step_rows(error_std, result.errors.shape[1])[None]
    rows = []
    for i, e in enumerate(result.energy):
        above = np.flatnonzero(e > threshold)
        first = int(above[0]) if len(above) else None
        rows.append({"episode": seqs.provenance["episodes"][i], "skill": str(seqs.labels[i]),
                     "peak_energy": float(e.max()), "first_flag_step": first, "steps_flagged": len(above),
                     "isolated_joint": None if first is None else isolate(weighted[i, first], model.channel_names)[0]})
    return rows


def evaluate(model: NeuralASM, normal: Sequences, faults: Sequences, mode: str = "offline", fpr: float = 0.01) -> dict[str, Any]:
    """Detection of the faulty episodes and false alarms on the normal ones at the calibrated threshold."""
    cal = model.calibration(mode, 1)
    if cal is None or fpr not in cal.thresholds:
        have = sorted(cal.thresholds) if cal is not None else []
        raise LogError(f"the model has no {mode} threshold at a false-positive rate of {fpr:g} (has {have}); "
                       "calibrate it on held-out normal episodes first")
    threshold = cal.thresholds[fpr]
    flagged = {name: _flags(model, s, mode, threshold, cal.error_std) for name, s in (("normal", normal), ("faults", faults))}
    peaks = [r["peak_energy"] for r in flagged["faults"] + flagged["normal"]]
    truth = [1] * len(flagged["faults"]) + [0] * len(flagged["normal"])
    return {
        "mode": mode, "fpr": fpr, "threshold": threshold,
        "detection_rate": float(np.mean([r["first_flag_step"] is not None for r in flagged["faults"]])),
        "normal_episodes_flagged": float(np.mean([r["first_flag_step"] is not None for r in flagged["normal"]])),
        "auroc": float(roc_auc_score(truth, peaks)),
        "episodes": flagged,
    }
