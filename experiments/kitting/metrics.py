"""Scores from the onset: each anomalous segment up to onset + delta, each normal one on a window
drawn from the same skill's anomaly windows' lengths (so that length or later course cannot carry
a result), decided by the served rule (`models.fault.is_fault`: a step's energy strictly above
the episode threshold)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from sklearn.metrics import roc_auc_score

from neural_asm.experiments.kitting.config import KittingConfig
from neural_asm.experiments.kitting.data import PERIOD_S, Segments
from neural_asm.experiments.kitting.methods import Scored
from neural_asm.models.fault import is_fault


def fpr_key(fpr: float) -> str:
    return f"{round(100 * fpr)}pct"


@dataclass(frozen=True)
class Windows:
    """Which test segments are scored, and the last step of each one's window at each delta."""

    anomalous: np.ndarray  # indices of scored anomalous test segments
    normal: np.ndarray  # indices of normal test segments
    ends: dict[float, np.ndarray]  # delta -> (len(anomalous) + len(normal),) last step, anomalies first

    @property
    def items(self) -> np.ndarray:
        return np.concatenate([self.anomalous, self.normal])

    @property
    def is_anomaly(self) -> np.ndarray:
        return np.r_[np.ones(len(self.anomalous), bool), np.zeros(len(self.normal), bool)]


def windows(test: Segments, config: KittingConfig, skills: tuple[str, ...], seed: int = 0,
            anomaly_runs: tuple[str, ...] | None = None) -> Windows:
    """Anomalies (not those labelled as no anomaly; with ``anomaly_runs``, only those of these runs)
    and normal segments of ``skills``; the normal windows' ends drawn, per delta, from the same
    skill's anomaly windows (all skills' if it has none)."""
    scored = np.isin(test.skills, skills)
    if anomaly_runs is not None:
        scored &= test.normal | np.isin(test.runs, anomaly_runs)
    anomalous = np.flatnonzero(scored & ~test.normal & ~np.isin(test.anomalies.astype(str), config.not_anomalies))
    normal = np.flatnonzero(scored & test.normal)
    rng = np.random.default_rng(seed)
    ends = {}
    for delta in config.deltas_s:
        a_end = np.clip(test.onsets[anomalous] + int(round(delta / PERIOD_S)), 0, test.lengths[anomalous] - 1)
        n_end = np.empty(len(normal), int)
        for k, i in enumerate(normal):
            pool = a_end[test.skills[anomalous] == test.skills[i]]
            n_end[k] = min(int(rng.choice(pool if len(pool) else a_end)), test.lengths[i] - 1)
        ends[delta] = np.r_[a_end, n_end]
    return Windows(anomalous, normal, ends)


def _peaks(energies: np.ndarray, rows: np.ndarray, ends: np.ndarray) -> np.ndarray:
    return np.array([energies[i, : e + 1].max() for i, e in zip(rows, ends)])


def _auroc(labels: np.ndarray, scores: np.ndarray) -> float | None:
    return float(roc_auc_score(labels, scores)) if 0 < labels.sum() < len(labels) else None


def _flagged(scored: Scored, fpr: float, rows: np.ndarray, ends: np.ndarray) -> np.ndarray:
    return np.array([bool(is_fault(scored.energies[i, : e + 1], scored.thresholds[fpr][i]).any())
                     for i, e in zip(rows, ends)])


def _mean(x: np.ndarray) -> float | None:
    return float(np.mean(x)) if len(x) else None


def method_metrics(scored: Scored, test: Segments, w: Windows, config: KittingConfig,
                   skills: tuple[str, ...]) -> tuple[dict[str, Any], np.ndarray]:
    """One training's metrics of one method over ``skills``, and its correct decisions per item at
    the headline delta and the served 1 % threshold (for paired comparisons)."""
    items, label = w.items, w.is_anomaly
    item_skill = test.skills[items]
    auroc: dict[str, Any] = {}
    per_skill: dict[str, Any] = {s: {"auroc": {}} for s in skills}
    for delta in config.deltas_s:
        peaks = _peaks(scored.energies, items, w.ends[delta])
        for s in skills:
            rows = item_skill == s
            per_skill[s]["auroc"][str(delta)] = _auroc(label[rows], peaks[rows])
        values = [v for v in (per_skill[s]["auroc"][str(delta)] for s in skills) if v is not None]
        auroc[str(delta)] = float(np.mean(values)) if values else None  # over the skills with anomalies
    head = w.ends[config.headline_delta_s]
    full = test.lengths[w.normal] - 1  # normal segments flagged: over all their steps
    out: dict[str, Any] = {"auroc": auroc, "per_skill": per_skill}
    correct = None
    for fpr in config.fprs:
        key = fpr_key(fpr)
        detected = _flagged(scored, fpr, w.anomalous, head[: len(w.anomalous)])
        flagged = _flagged(scored, fpr, w.normal, full)
        out[f"detected_{key}"], out[f"normal_flagged_{key}"] = _mean(detected), _mean(flagged)
        for s in skills:
            d, f = detected[test.skills[w.anomalous] == s], flagged[test.skills[w.normal] == s]
            per_skill[s][f"detected_{key}"], per_skill[s][f"normal_flagged_{key}"] = _mean(d), _mean(f)
            if fpr == config.fprs[0] and len(d) and len(f):
                per_skill[s]["balanced_accuracy"] = 0.5 * (float(d.mean()) + 1 - float(f.mean()))
        if fpr == config.fprs[0]:
            correct = np.r_[detected, ~flagged]
    peaks = _peaks(scored.energies, items, head)
    types = test.anomalies[w.anomalous].astype(str)
    out["per_type"] = {t: {"n": int((types == t).sum()),
                           f"auroc_{config.headline_delta_s}": _auroc(np.r_[np.ones((types == t).sum()), np.zeros(len(w.normal))],
                                                                      np.r_[peaks[: len(w.anomalous)][types == t],
                                                                            peaks[len(w.anomalous):]])}
                       for t in sorted(set(types))}
    out.update(_delays(scored, test, w.anomalous, config.fprs[0]))
    return out, correct  # type: ignore[return-value]


def _delays(scored: Scored, test: Segments, rows: np.ndarray, fpr: float) -> dict[str, float | None]:
    """First flag at or after the onset (ms after it), within the segment; and the share flagged before it."""
    delays, early = [], []
    for i in rows:
        onset, n = max(int(test.onsets[i]), 0), int(test.lengths[i])
        flags = is_fault(scored.energies[i, :n], scored.thresholds[fpr][i])
        early.append(bool(flags[:onset].any()))
        after = np.flatnonzero(flags[onset:])
        if len(after):
            delays.append(1000 * PERIOD_S * after[0])
    return {"delay_ms_median": float(np.median(delays)) if delays else None,
            "delay_ms_p95": float(np.percentile(delays, 95)) if delays else None,
            "flagged_before_onset": _mean(np.array(early)), "flagged_after_onset": len(delays) / max(len(rows), 1)}


def across(trainings: list[Any]) -> tuple[Any, Any]:
    """The mean of each number over trainings, and its [min, max]: trees of one shape, a key
    missing from some (an anomaly type no test run of a split holds) taken over those that have it."""
    first = trainings[0]
    if isinstance(first, dict):
        keys = dict.fromkeys(k for t in trainings for k in t)
        pairs = {k: across([t[k] for t in trainings if k in t]) for k in keys}
        return {k: m for k, (m, _) in pairs.items()}, {k: r for k, (_, r) in pairs.items()}
    if isinstance(first, (int, float)) and not isinstance(first, bool) and all(t is not None for t in trainings):
        values = np.array(trainings, float)
        return (int(first) if isinstance(first, int) and (values == first).all() else float(values.mean()),
                [float(values.min()), float(values.max())])
    return first, None
