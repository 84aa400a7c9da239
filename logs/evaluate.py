"""Fault detection on logged episodes, as ``nasm faults`` measures it on simulated ones, for
logs where only whole episodes are known to be normal or faulty: which episodes a checkpoint's
calibrated threshold flags, where first, which joint it blames, and how well episode peak
energies separate the two sets. Steps are flagged by the service's own rule
(``models.fault.flag_steps``, the episode threshold by default), so the false alarms reported
here are the ones a session of ``nasm serve`` raises on the same episodes."""

from __future__ import annotations

from typing import Any

import numpy as np
from sklearn.metrics import roc_auc_score

from neural_asm.logs.errors import LogError
from neural_asm.models.asm import NeuralASM
from neural_asm.models.calibration import Calibration
from neural_asm.models.fault import ThresholdKind, flag_steps, isolate, threshold_for
from neural_asm.models.sequences import Sequences


def _flags(model: NeuralASM, seqs: Sequences, mode: str, cal: Calibration, fpr: float,
           kind: ThresholdKind) -> list[dict[str, Any]]:
    result = model.score(seqs.data, mode, 1, True)
    flags, _ = flag_steps(result.energy, cal, fpr, kind)
    weighted = cal.weigh(result.errors)
    rows = []
    for i, e in enumerate(result.energy):
        above = np.flatnonzero(flags[i])
        first = int(above[0]) if len(above) else None
        rows.append({"episode": seqs.episodes[i].origin, "number": seqs.episodes[i].number, "skill": str(seqs.labels[i]),
                     "peak_energy": float(e.max()), "first_flag_step": first, "steps_flagged": len(above),
                     "isolated_joint": None if first is None else isolate(weighted[i, first], model.channel_names)[0]})
    return rows


def evaluate(model: NeuralASM, normal: Sequences, faults: Sequences, mode: str = "offline", fpr: float = 0.01,
             kind: ThresholdKind = "episode") -> dict[str, Any]:
    """Detection of the faulty episodes and false alarms on the normal ones, decided as the service decides."""
    cal = model.calibration(mode, 1)
    try:
        if cal is None:
            raise KeyError(f"no {mode} calibration")
        threshold_for(cal, fpr, 0, kind)
    except (KeyError, ValueError) as exc:
        raise LogError(f"the model has no {kind} threshold for {mode} recall at a false-positive rate of {fpr:g} "
                       f"({exc.args[0]}); calibrate it on held-out normal episodes first (nasm calibrate)") from None
    assert cal is not None
    flagged = {name: _flags(model, s, mode, cal, fpr, kind) for name, s in (("normal", normal), ("faults", faults))}
    peaks = [r["peak_energy"] for r in flagged["faults"] + flagged["normal"]]
    truth = [1] * len(flagged["faults"]) + [0] * len(flagged["normal"])
    threshold = threshold_for(cal, fpr, 0, kind) if kind != "per_step" else None
    return {
        "mode": mode, "fpr": fpr, "threshold_kind": kind, "threshold": threshold,
        "detection_rate": float(np.mean([r["first_flag_step"] is not None for r in flagged["faults"]])),
        "normal_episodes_flagged": float(np.mean([r["first_flag_step"] is not None for r in flagged["normal"]])),
        "auroc": float(roc_auc_score(truth, peaks)),
        "episodes": flagged,
    }
