"""How a method's energies become flags and rates, the same for every method and every set.

Thresholds come from the calibration split at `alpha`: the episode threshold is the one a
checkpoint stores and the service applies (`models.calibration.Thresholds`: the peak energy that
a share `alpha` of normal episodes exceed; at the benchmark's 300 calibration episodes and 1 % it
is the split-conformal rank); the time-varying one (per-step scales from the precision split) is
split-conformal. A fault is detected when its energy crosses the threshold at or after its onset.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from sklearn.metrics import roc_auc_score

from neural_asm.experiments.varied.data import VariedBenchmark
from neural_asm.models.calibration import Thresholds
from neural_asm.models.config import SCORING
from neural_asm.models.conformal import TimeVaryingThreshold, binomial_interval
from neural_asm.sim.config import SIM

ALPHA = SCORING.default_fpr  # the episode false-alarm rate every method is held to
VALIDATION = "val_faults"  # the validation faults' energies: read by the pair's choice only


@dataclass(frozen=True)
class Outcome:
    """Per-episode results of one method under one threshold rule."""

    detected: np.ndarray  # (F,) bool
    first: np.ndarray  # (F,) first crossing step at or after onset, -1 if none
    fault_score: np.ndarray  # (F,) peak energy from the onset on (relative to the threshold)
    normal_flagged: np.ndarray  # (N_test,) bool
    ood_flagged: np.ndarray  # (N_ood,) bool
    normal_score: np.ndarray  # (N_test,)
    ood_score: np.ndarray  # (N_ood,)


def after_onset(e: np.ndarray, onset: np.ndarray) -> np.ndarray:
    """Energies (N, T) with the steps before each episode's onset masked: a fault is only
    credited for what the monitor flags once it has begun."""
    steps = np.arange(e.shape[1])
    return np.where(steps[None] >= onset[:, None], e, -np.inf)


def outcomes(e: dict[str, np.ndarray], onset: np.ndarray, alpha: float = ALPHA) -> dict[str, Outcome]:
    """The served episode threshold and time-varying conformal thresholds."""
    out = {}
    thr = Thresholds.of(e["calibration"], alpha).episode
    faults = after_onset(e["faults"], onset)
    over = faults > thr
    out["episode"] = Outcome(over.any(axis=1), np.where(over.any(axis=1), over.argmax(axis=1), -1),
                             faults.max(axis=1) / thr, e["test"].max(axis=1) > thr, e["ood"].max(axis=1) > thr,
                             e["test"].max(axis=1) / thr, e["ood"].max(axis=1) / thr)
    tv = TimeVaryingThreshold().fit(e["precision"], e["calibration"], alpha)
    rel = {k: e[k] / tv.thresholds[: e[k].shape[1]] for k in ("test", "ood", "faults")}
    over = after_onset(rel["faults"], onset) > 1.0
    out["time_varying"] = Outcome(over.any(axis=1), np.where(over.any(axis=1), over.argmax(axis=1), -1),
                                  after_onset(rel["faults"], onset).max(axis=1), rel["test"].max(axis=1) > 1.0,
                                  rel["ood"].max(axis=1) > 1.0, rel["test"].max(axis=1), rel["ood"].max(axis=1))
    return out


def summary(o: Outcome, bench: VariedBenchmark) -> dict:
    visible = bench.visible
    n_test, k_test = len(o.normal_flagged), int(o.normal_flagged.sum())
    scores = np.concatenate([o.fault_score[visible], o.normal_score])
    labels = np.concatenate([np.ones(visible.sum()), np.zeros(n_test)])
    delay = (o.first - bench.onset)[o.detected & visible]
    families = {}
    for kind in np.unique(bench.kinds):
        m = bench.kinds == kind
        families[str(kind)] = {"n": int(m.sum()), "visible": int((m & visible).sum()),
                               "detection": float(o.detected[m].mean()),
                               "detection_visible": float(o.detected[m & visible].mean()) if (m & visible).any() else None}
    return {
        "detection": float(o.detected[visible].mean()),
        "detection_all_faults": float(o.detected.mean()),
        "normal_episode_false_alarm": k_test / n_test,
        "normal_episode_false_alarm_interval95": list(binomial_interval(k_test, n_test)),
        "benign_ood_false_alarm": float(o.ood_flagged.mean()),
        "auroc": float(roc_auc_score(labels, scores)),
        "median_delay_steps": float(np.median(delay)) if len(delay) else None,
        "per_family": families,
        "consequential": consequential(o, bench),
    }


def consequential(o: Outcome, bench: VariedBenchmark) -> dict:
    """Faults whose task failed where their twin's succeeded, scored as robot failure detectors
    are: caught at the episode threshold, how long before the episode's end (when success is
    judged) the first flag came, and the AUROC of their score against every successful run
    (the normal test episodes and the benign out-of-range runs that placed their cube)."""
    failed, normal_placed, placed = bench.consequence == "consequential", bench.test_success, bench.ood_success
    if not failed.any():
        return {"n": 0, "detection": None, "lead_time_s_median": None, "auroc": None,
                "benign_ood_false_alarm": None, "per_family": {}}
    caught = failed & o.detected
    lead_s = (bench.faults.data.shape[1] - o.first[caught]) / SIM.timing.observation_hz
    scores = np.concatenate([o.fault_score[failed], o.normal_score[normal_placed], o.ood_score[placed]])
    labels = np.concatenate([np.ones(failed.sum()), np.zeros(normal_placed.sum() + placed.sum())])
    return {"n": int(failed.sum()), "detection": float(caught.sum() / failed.sum()),
            "lead_time_s_median": float(np.median(lead_s)) if caught.any() else None,
            "auroc": float(roc_auc_score(labels, scores)),
            "benign_ood_false_alarm": float(o.ood_flagged[placed].mean()) if placed.any() else None,
            "per_family": {str(kind): {"n": int((failed & (bench.kinds == kind)).sum()),
                                       "detection": float(o.detected[failed & (bench.kinds == kind)].mean())}
                           for kind in np.unique(bench.kinds[failed])}}
