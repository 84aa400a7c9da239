"""``run(config) -> KittingResult``: the kitting benchmark from the clone's folder to its metrics."""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from tqdm import tqdm

from neural_asm.experiments.kitting.config import KittingConfig
from neural_asm.experiments.kitting.data import Segments, Split, read_segments, split_runs
from neural_asm.experiments.kitting.methods import (INFO, METHODS, Scored, Sets, fit_network, score_baselines, score_network,
                                                    score_cross_fitted, score_per_skill, score_told)
from neural_asm.experiments.kitting.metrics import Windows, across, method_metrics, windows
from neural_asm.models import checkpoint
from neural_asm.models.asm import NeuralASM
from neural_asm.models.conformal import mcnemar_exact

PUBLISHED = {
    "paper": {"source": "Wu et al., J. Intell. Robot. Syst. 2022, doi 10.1007/s10846-021-01496-x",
              "figure": "94 % average anomaly identification accuracy",
              "protocol": "multimodal LSTM predictor per skill; anomalies identified over whole segments (not from their "
                          "onset); split by segment"},
    "results_log": {"source": "the repository's results.log (skill 4, LSTM with dropout, force and torque norms)",
                    "tp": 23, "tn": 75, "fp": 0, "fn": 0, "accuracy": 1.0,
                    "protocol": "skill 4 only; whole segments; its own train/test split"},
}


@dataclass
class KittingResult:
    config: dict[str, Any]
    split: dict[str, Any]
    counts: dict[str, Any]
    methods: dict[str, dict[str, Any]]  # name -> mean over trainings (with "range" and "trainings")
    few: dict[str, dict[str, Any]]  # skills 7-9: the one network and the told template
    paired: dict[str, Any]
    whole_runs: dict[str, Any]
    timeline: dict[str, Any]  # one anomalous segment's energies against the threshold, for the figure
    seconds: float
    model_path: str = ""
    headline: dict[str, Any] = field(default_factory=dict)


def make_sets(segs: Segments, split: Split) -> Sets:
    """Train: normal segments of the training runs. Precision and threshold halves: normal segments of
    the calibration runs, alternate runs each. Test: normal segments of the test runs and every
    anomalous segment (none is ever trained or calibrated on) of a skill that has normal ones."""
    normal = segs.normal
    cal_runs = np.array(split.calibration)
    known = np.isin(segs.skills, np.unique(segs.skills[normal]))
    return Sets(segs.take(normal & split.side(segs.runs, "train")),
                segs.take(normal & np.isin(segs.runs, cal_runs[0::2])),
                segs.take(normal & np.isin(segs.runs, cal_runs[1::2])),
                segs.take(known & ((normal & split.side(segs.runs, "test")) | ~normal)))


def _one_training(sets: Sets, config: KittingConfig, seed: int, progress: tqdm) -> tuple[dict[str, Scored], NeuralASM]:
    model = fit_network(sets.train, config, seed)
    progress.update()
    # The served calibration (skill recognised, centred) last: it is the one the model keeps.
    scored = {"nasm_one_pooled": score_network(model, sets, config.recall_mode, False, config.fprs),
              "nasm_one_online": score_network(model, sets, "online", True, config.fprs),
              "nasm_one_plan": score_network(model, sets, "plan", True, config.fprs),
              "nasm_one": score_network(model, sets, config.recall_mode, True, config.fprs)}
    scored["nasm_one_told"] = score_told(model, sets, config.recall_mode, config.fprs)
    scored["nasm_one_cross_fitted"] = score_cross_fitted(model, scored["nasm_one"], sets, config)
    scored["nasm_per_skill"] = score_per_skill(sets, config, seed, config.headline_skills)
    progress.update()
    scored.update(score_baselines(sets, config, seed, learned_only=seed != config.seeds[0]))
    progress.update()
    return scored, model


def _paired(correct: dict[str, list[np.ndarray]], methods: dict[str, dict[str, Any]], delta: str) -> dict[str, Any]:
    """The featured network against the rival with the highest AUROC at the headline delta (not a
    trivial one, not itself a Neural ASM): items one gets right and the other wrong, summed over
    the trainings they share; exact McNemar p-value."""
    rivals = [m for m in methods if not INFO[m].is_neural_asm and not INFO[m].trivial]
    best = max(rivals, key=lambda m: methods[m]["auroc"][delta] or 0.0)
    rival = correct[best]  # a template's one "training" faces each of the network's
    pairs = [(a, rival[k % len(rival)]) for k, a in enumerate(correct["nasm_one"])]
    nasm_only = int(sum((a & ~b).sum() for a, b in pairs))
    rival_only = int(sum((~a & b).sum() for a, b in pairs))
    return {"baseline": best, "nasm_only": nasm_only, "baseline_only": rival_only,
            "p_value": float(mcnemar_exact(nasm_only, rival_only)), "trainings": len(pairs),
            "items": "anomalies detected and normal test segments not flagged, served 1 % threshold, delta "
                     f"{delta} s, summed over trainings"}


def run(config: KittingConfig) -> KittingResult:
    start = time.perf_counter()
    segs = read_segments(config.data)
    split = split_runs(segs.runs, config.train_fraction, config.split_seed)
    sets = make_sets(segs, split)
    skills = config.headline_skills
    few = tuple(s for s in config.few_skills if s in set(sets.train.skills) and s in set(sets.test.skills))
    w = windows(sets.test, config, skills)
    w_few = windows(sets.test, config, few) if few else None
    w_own = windows(sets.test, config, skills, anomaly_runs=split.test)  # the confound measured, not only named
    per_training: dict[str, list[dict[str, Any]]] = {}
    own_training: dict[str, list[dict[str, Any]]] = {}
    few_training: dict[str, list[dict[str, Any]]] = {}
    correct: dict[str, list[np.ndarray]] = {}
    models: list[NeuralASM] = []
    timeline: dict[str, Any] = {}
    with tqdm(total=3 * len(config.seeds), desc="kitting: trainings", unit="step") as progress:
        for seed in config.seeds:
            scored, model = _one_training(sets, config, seed, progress)
            models.append(model)
            for name, s in scored.items():
                metrics, ok = method_metrics(s, sets.test, w, config, skills)
                per_training.setdefault(name, []).append(metrics)
                correct.setdefault(name, []).append(ok)
                own_training.setdefault(name, []).append(method_metrics(s, sets.test, w_own, config, skills)[0])
                if w_few is not None and name in ("nasm_one", "template_told"):
                    few_training.setdefault(name, []).append(method_metrics(s, sets.test, w_few, config, few)[0])
            if seed == config.seeds[0]:
                timeline = _timeline(scored["nasm_one"], sets.test, w, config)
    methods = {}
    for m in METHODS:
        mean, spread = across(per_training[m.name])
        methods[m.name] = {"is_neural_asm": m.is_neural_asm, "told_skill": m.told_skill, "label": m.label,
                           "trainings": len(per_training[m.name]), **mean, "range": spread,
                           "anomalies_from_test_runs": _own_runs(across(own_training[m.name])[0], config)}
    few_out = {name: {"trainings": len(v), **across(v)[0]} for name, v in few_training.items()}
    path = config.out / "kitting_model.safetensors"
    checkpoint.save(models[0], path)
    test = sets.test
    counts = {"segments": len(segs), "train_normal": len(sets.train), "precision_normal": len(sets.precision),
              "threshold_normal": len(sets.threshold), "test_normal": int(test.normal.sum()),
              "test_anomalous_scored": len(w.anomalous),
              "n_normal_train": {str(s): int((sets.train.skills == s).sum()) for s in sorted(set(segs.skills))},
              "anomalies_from_test_runs": len(w_own.anomalous),
              "anomalies_from_test_runs_per_skill": {s: int((test.skills[w_own.anomalous] == s).sum()) for s in skills}}
    for name in methods:
        for s, row in methods[name]["per_skill"].items():
            row["n_normal_train"] = counts["n_normal_train"].get(s, 0)
    result = KittingResult(
        config={"network": config.network.to_dict(), "trainings": config.trainings, "seeds": list(config.seeds),
                "split_seed": config.split_seed, "deltas_s": list(config.deltas_s), "recall_mode": config.recall_mode,
                "fprs": list(config.fprs), "lstm_epochs": config.lstm_epochs},
        split={"train": list(split.train), "calibration": list(split.calibration), "test": list(split.test),
               "seed": split.seed},
        counts=counts, methods=methods, few=few_out,
        paired=_paired(correct, methods, str(config.headline_delta_s)),
        whole_runs={}, timeline=timeline, seconds=0.0, model_path=str(path))
    if config.whole_runs:
        from neural_asm.experiments.kitting.whole_runs import score_whole_runs

        result.whole_runs = score_whole_runs(config, split, models)
    result.seconds = round(time.perf_counter() - start, 1)
    result.headline = headline(result, config)
    return result


def _own_runs(metrics: dict[str, Any], config: KittingConfig) -> dict[str, Any]:
    """The headline numbers of one method scored on the anomalies of test runs only."""
    delta = str(config.headline_delta_s)
    return {"auroc": metrics["auroc"], "detected_1pct": metrics["detected_1pct"], "per_type": metrics["per_type"],
            "per_skill_auroc": {s: row["auroc"][delta] for s, row in metrics["per_skill"].items()}}


def _timeline(scored: Scored, test: Segments, w: Windows, config: KittingConfig) -> dict[str, Any]:
    """A skill-5 no_object segment (else the first anomaly): its energies, threshold and onset."""
    rows = [i for i in w.anomalous if test.anomalies[i] == "no_object"] or list(w.anomalous)
    i = int(rows[0])
    n = int(test.lengths[i])
    return {"origin": test.origins[i], "skill": str(test.skills[i]), "anomaly": str(test.anomalies[i]),
            "energies": scored.energies[i, :n].tolist(), "threshold": float(scored.thresholds[config.fprs[0]][i]),
            "onset_step": int(test.onsets[i])}


def headline(result: KittingResult, config: KittingConfig) -> dict[str, Any]:
    keys = ("is_neural_asm", "told_skill", "trainings", "auroc", "per_skill", "per_type", "detected_1pct",
            "normal_flagged_1pct", "delay_ms_median", "delay_ms_p95")
    return {"task": "kitting", "featured": "nasm_one", "deltas_s": list(config.deltas_s),
            "methods": {name: {k: m[k] for k in keys} for name, m in result.methods.items()},
            "paired": {k: result.paired[k] for k in ("baseline", "nasm_only", "baseline_only", "p_value")},
            "anomalies_from_test_runs": {name: m["anomalies_from_test_runs"] for name, m in result.methods.items()},
            "whole_runs": {k: result.whole_runs.get(k) for k in (
                "n_runs", "n_anomalies", "n_clean_phases", "flagged_within_1s", "flagged_early",
                "clean_phases_flagged", "skill_recognised")},
            "published": PUBLISHED}
