"""Detection and isolation metrics of one method under one weighting of its errors.

A fault counts as detected when some step at or after its fault step exceeds the
threshold (steps before it are normal operation). Per-step false-positive rates are
the paper's percentiles; because 15 steps give 15 chances, the share of whole normal
episodes with a false alarm is reported too, and thresholds calibrated on an episode's
peak energy are evaluated beside them.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from sklearn.metrics import roc_auc_score

from neural_asm.experiments.fault_sweep.data import Benchmark
from neural_asm.experiments.twins import VISIBLE_K, visible_from, whitened_deviation
from neural_asm.models.calibration import Thresholds, estimate
from neural_asm.models.config import SCORING
from neural_asm.models.normaliser import Normaliser
from neural_asm.models.fault import isolated_joint, joint_channels
from neural_asm.models.scoring import energy

FPRS = SCORING.fprs  # the thresholds a model calibrates
MAIN_FPR = SCORING.default_fpr  # the one its decisions use
BOOTSTRAP = 2000  # resamples for the 95 % intervals


def interval95(per_item: np.ndarray, seed: int = 0) -> list[float]:
    """Percentile bootstrap interval of the mean of per-episode values (thresholds held fixed:
    the spread of the test episodes, not of the calibration). For detection it resamples the
    designed fault grid, so read it as the spread over faults like these, not over a population."""
    if len(per_item) == 0:
        raise ValueError("no episodes to resample")
    rng = np.random.default_rng(seed)
    means = per_item[rng.integers(0, len(per_item), (BOOTSTRAP, len(per_item)))].mean(axis=1)
    return [float(v) for v in np.quantile(means, [0.025, 0.975])]


@dataclass(frozen=True)
class Errors:
    """Normalised errors (N, T, D) of one method on every set."""

    precision: np.ndarray
    calibration: np.ndarray
    normal_test: np.ndarray
    faults: np.ndarray


@dataclass(frozen=True)
class Weighted:
    """Energies (N, T) and weighted errors (N, T, D) under one weighting."""

    calibration: np.ndarray
    normal_test: np.ndarray
    faults: np.ndarray
    fault_errors: np.ndarray


WEIGHTINGS = ("raw", "precision", "whitened")  # every method; z-score methods add "demo_std"


def weigh(errors: Errors, weighting: str, demo_spread: dict[str, np.ndarray] | None = None) -> Weighted:
    """raw: plain squared errors; precision: divided by each step's error spread on the
    precision split; whitened: as precision, then whitened by each step's precision matrix
    from the same split (isolation still reads the spread-divided errors); demo_std:
    divided by the demonstrations' std (z-score baselines)."""
    sets = ("calibration", "normal_test", "faults")
    if weighting == "raw":
        std = {k: 1.0 for k in sets}
    elif weighting in ("precision", "whitened"):  # as the model's own calibration does it
        cal = estimate("sweep", 1, errors.precision, "precision split",
                       "full" if weighting == "whitened" else "diagonal")
        e = {k: cal.energy(getattr(errors, k)) for k in sets}
        return Weighted(e["calibration"], e["normal_test"], e["faults"], cal.weigh(errors.faults))
    elif weighting == "demo_std":
        assert demo_spread is not None
        std = {k: np.maximum(demo_spread[k], SCORING.error_std_floor) for k in sets}
    else:
        raise ValueError(f"unknown weighting {weighting!r}")
    w = {k: getattr(errors, k) / std[k] for k in std}
    return Weighted(energy(w["calibration"]), energy(w["normal_test"]), energy(w["faults"]), w["faults"])


def first_crossing(energies: np.ndarray, thresholds: np.ndarray, from_step: np.ndarray) -> np.ndarray:
    """First step >= from_step whose energy exceeds its threshold, or -1 (per episode)."""
    steps = np.arange(energies.shape[1])
    over = (energies > thresholds) & (steps[None] >= from_step[:, None])
    return np.where(over.any(axis=1), over.argmax(axis=1), -1)


def evaluate(w: Weighted, channel_names: tuple[str, ...], fault_step: np.ndarray, fault_joint: np.ndarray) -> tuple[dict, dict]:
    """Summary metrics and per-episode outcomes (at the 1 % per-step threshold)."""
    steps = w.faults.shape[1]
    rows = np.arange(len(fault_step))
    summary: dict = {"detection_rate": {}, "measured_fpr": {}, "episode_false_alarm_rate": {},
                     "detection_rate_step_thresholds": {}, "measured_fpr_step_thresholds": {},
                     "detection_rate_episode_calibrated": {}, "episode_false_alarm_rate_episode_calibrated": {}}
    outcome: dict = {}
    for fpr in FPRS:
        key = f"{fpr:.2f}"
        t = Thresholds.of(w.calibration, fpr)  # as a model calibrates them for the service
        single, per_step, peak = t.step, t.per_step, t.episode
        first = first_crossing(w.faults, np.full(steps, single), fault_step)
        first_ps = first_crossing(w.faults, per_step, fault_step)
        summary["detection_rate"][key] = float((first >= 0).mean())
        summary["measured_fpr"][key] = float((w.normal_test > single).mean())
        summary["episode_false_alarm_rate"][key] = float((w.normal_test > single).any(axis=1).mean())
        summary["detection_rate_step_thresholds"][key] = float((first_ps >= 0).mean())
        summary["measured_fpr_step_thresholds"][key] = float((w.normal_test > per_step).mean())
        after = np.where(np.arange(steps)[None] >= fault_step[:, None], w.faults, -np.inf)
        summary["detection_rate_episode_calibrated"][key] = float((after.max(axis=1) > peak).mean())
        summary["episode_false_alarm_rate_episode_calibrated"][key] = float((w.normal_test.max(axis=1) > peak).mean())
        if fpr == MAIN_FPR:
            outcome["first_detection_step"] = first
            outcome["threshold"] = single
            summary["interval95"] = {
                "detection_rate": interval95((first >= 0).astype(float)),
                "measured_fpr": interval95((w.normal_test > single).mean(axis=1)),
                "episode_false_alarm_rate": interval95((w.normal_test > single).any(axis=1).astype(float)),
            }
    isolated = isolated_joint(w.fault_errors, channel_names) + 1  # (F, T): joint number, as the service isolates
    at_fault = isolated[rows, fault_step]
    first = outcome["first_detection_step"]
    detected = first >= 0
    at_detection = isolated[rows, np.where(detected, first, 0)]
    summary["isolation_accuracy_at_fault_step"] = float((at_fault == fault_joint).mean())
    summary["isolation_accuracy_at_detection"] = (
        float((at_detection[detected] == fault_joint[detected]).mean()) if detected.any() else 0.0
    )
    scores = np.concatenate([w.faults.max(axis=1), w.normal_test.max(axis=1)])
    labels = np.concatenate([np.ones(len(w.faults)), np.zeros(len(w.normal_test))])
    summary["auroc"] = float(roc_auc_score(labels, scores))
    # Immediate detection: at the fault step itself (ceiling: faults visible there).
    summary["detection_rate_at_fault_step"] = float((first == fault_step).mean())
    delay = (first - fault_step)[detected]
    summary["median_detection_delay_steps"] = float(np.median(delay)) if detected.any() else None
    outcome.update(isolated_at_fault_step=at_fault, isolated_at_detection=np.where(detected, at_detection, 0),
                   peak_energy=w.faults.max(axis=1))
    return summary, outcome


def ceilings(bench: Benchmark, norm: Normaliser, k: float = VISIBLE_K) -> dict:
    """What an oracle that knows each fault's no-fault twin could reach (in `norm`'s units).

    Deviation from the twin is whitened by normal variation (per-skill, per-step std of
    held-out normal episodes, `experiments.twins`). A fault is *visible* when some channel deviates by more
    than k normal standard deviations at or after its fault step. The isolation ceiling
    at the fault step counts faults whose own joint deviates most among the joints at
    that step, by more than k standard deviations: a 0-degree overshoot changes nothing
    at its own step, so about 1/7 of the grid cannot be isolated there.
    """
    precision, fault_step = bench.normal.precision, bench.fault_step
    dev = whitened_deviation(norm.normalise(bench.faults.data), norm.normalise(bench.twins.data), bench.faults.labels,
                             norm.normalise(precision.data), precision.labels)
    rows = np.arange(len(dev))
    visible = visible_from(dev, fault_step, k)
    at = dev[rows, fault_step][:, np.array(joint_channels(bench.normal.channel_names))]
    isolable = (at.argmax(axis=1) + 1 == bench.fault_joint) & (at.max(axis=1) > k)
    return {
        "oracle_detection_rate": float(visible.mean()),
        "invisible_faults": int((~visible).sum()),
        "visible_at_fault_step": float((dev[rows, fault_step].max(axis=1) > k).mean()),
        "isolation_ceiling_at_fault_step": float(isolable.mean()),
        "whitening_k_sigma": k,
        "visible": visible,
    }
