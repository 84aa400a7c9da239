"""``run(config) -> KittingResult``: the kitting benchmark from the clone's folder to its metrics."""

from __future__ import annotations

import time
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
from tqdm import tqdm

from neural_asm.experiments.kitting.config import KittingConfig
from neural_asm.experiments.kitting.data import Segments, Split, read_segments, split_runs
from neural_asm.experiments.kitting.methods import (INFO, METHODS, Scored, Sets, fit_network, score_baselines, score_network,
                                                    score_cross_fitted, score_per_skill, score_told)
from neural_asm.experiments.kitting.metrics import Windows, across, method_metrics, windows
from neural_asm.experiments.kitting.skill_methods import fit_skill_memory, score_skill_memory, score_template_likelihood
from neural_asm.models import checkpoint
from neural_asm.models.asm import NeuralASM
from neural_asm.models.conformal import mcnemar_exact
from neural_asm.models.skill_context import SkillMemory

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
    methods: dict[str, dict[str, Any]]  # name -> mean over the trainings of every split (with "range" and "trainings")
    few: dict[str, dict[str, Any]]  # skills 7-9: the one network and the told template
    paired: dict[str, Any]  # the skill memory not told against the strongest rival not told
    whole_runs: dict[str, Any]  # "not_told" and "told": through nasm replay to nasm serve
    timeline: dict[str, Any]  # one anomalous segment's energies against the threshold, for the figure
    seconds: float
    model_path: str = ""
    paired_told: dict[str, Any] = field(default_factory=dict)  # the memory told against the strongest rival told
    # the same tests against the strongest rivals at the memory's own (cross-fitted) threshold rule
    paired_cross_fitted: dict[str, Any] = field(default_factory=dict)
    paired_told_cross_fitted: dict[str, Any] = field(default_factory=dict)
    by_split: dict[str, dict[str, dict[str, Any]]] = field(default_factory=dict)  # split -> method -> headline numbers
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


def _one_training(sets: Sets, config: KittingConfig, seed: int,
                  progress: tqdm) -> tuple[dict[str, Scored], NeuralASM, SkillMemory]:
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
    memory = fit_skill_memory(sets.train, config, seed)
    if seed == config.seeds[0]:
        scored.update(score_template_likelihood(memory, sets, config))
    scored.update(score_skill_memory(memory, sets, config))
    progress.update()
    return scored, model, memory


@dataclass
class SplitRun:
    """One run-wise split's trainings: each method's metrics and served decisions per training
    (a method that depends on no training has one), the counts, the models and the memories."""

    split: Split
    counts: dict[str, Any]
    per_training: dict[str, list[dict[str, Any]]]
    own_training: dict[str, list[dict[str, Any]]]  # on the anomalies of test runs only
    few_training: dict[str, list[dict[str, Any]]]  # skills 7-9: the one network and the told template
    correct: dict[str, list[np.ndarray]]  # the served decisions each item gets right (`method_metrics`)
    models: list[NeuralASM]
    memories: list[SkillMemory]
    timeline: dict[str, Any]


def run_split(segs: Segments, config: KittingConfig, progress: bool = True) -> SplitRun:
    """Every method's trainings on the split ``config.split_seed`` draws (one process: a worker's job)."""
    with tqdm(total=3 * len(config.seeds), desc=f"kitting split {config.split_seed}: trainings", unit="step",
              disable=not progress) as bar:
        return _trainings(segs, config, bar)


def _trainings(segs: Segments, config: KittingConfig, progress: tqdm) -> SplitRun:
    split = split_runs(segs.runs, config.train_fraction, config.split_seed)
    sets = make_sets(segs, split)
    skills = config.headline_skills
    few = tuple(s for s in config.few_skills if s in set(sets.train.skills) and s in set(sets.test.skills))
    w = windows(sets.test, config, skills)
    w_few = windows(sets.test, config, few) if few else None
    w_own = windows(sets.test, config, skills, anomaly_runs=split.test)  # the confound measured, not only named
    out = SplitRun(split, {}, {}, {}, {}, {}, [], [], {})
    for seed in config.seeds:
        scored, model, memory = _one_training(sets, config, seed, progress)
        out.models.append(model)
        out.memories.append(memory)
        for name, s in scored.items():
            metrics, ok = method_metrics(s, sets.test, w, config, skills)
            out.per_training.setdefault(name, []).append(metrics)
            out.correct.setdefault(name, []).append(ok)
            out.own_training.setdefault(name, []).append(method_metrics(s, sets.test, w_own, config, skills)[0])
            if w_few is not None and name in ("nasm_one", "template_told"):
                out.few_training.setdefault(name, []).append(method_metrics(s, sets.test, w_few, config, few)[0])
        if seed == config.seeds[0]:
            out.timeline = _timeline(scored["nasm_one"], sets.test, w, config)
    test = sets.test
    out.counts = {"segments": len(segs), "train_normal": len(sets.train), "precision_normal": len(sets.precision),
                  "threshold_normal": len(sets.threshold), "test_normal": int(test.normal.sum()),
                  "test_anomalous_scored": len(w.anomalous), "test_normal_scored": len(w.normal),
                  "n_normal_train": {str(s): int((sets.train.skills == s).sum()) for s in sorted(set(segs.skills))},
                  "anomalies_from_test_runs": len(w_own.anomalous),
                  "anomalies_from_test_runs_per_skill": {s: int((test.skills[w_own.anomalous] == s).sum())
                                                         for s in skills}}
    return out


def _paired(runs: list[SplitRun], methods: dict[str, dict[str, Any]], featured: str, delta: str,
            cross_fitted: bool = False) -> dict[str, Any]:
    """``featured`` against the rival told the skill as it is (or not) with the highest AUROC at
    the headline delta (not a trivial one, not itself a Neural ASM), at its own held-out threshold
    or, ``cross_fitted``, at the featured memory's rule: items one gets right and the other wrong,
    summed over the trainings and splits they share; exact McNemar p-value."""
    told = INFO[featured].told_skill
    rivals = [m for m in methods if not INFO[m].is_neural_asm and not INFO[m].trivial and INFO[m].told_skill == told
              and INFO[m].cross_fitted == cross_fitted]
    best = max(rivals, key=lambda m: methods[m]["auroc"][delta] or 0.0)
    counts = {str(one.split.seed): _discordant(one, featured, best) for one in runs}
    nasm_only = sum(c["nasm_only"] for c in counts.values())
    rival_only = sum(c["baseline_only"] for c in counts.values())
    return {"featured": featured, "baseline": best, "nasm_only": nasm_only, "baseline_only": rival_only,
            "p_value": float(mcnemar_exact(nasm_only, rival_only)),
            "trainings": sum(len(one.correct[featured]) for one in runs), "by_split": counts,
            "items": "anomalies detected and normal test segments not flagged, served 1 % threshold, delta "
                     f"{delta} s, summed over trainings and splits (by_split: each split's)"}


def _discordant(one: SplitRun, featured: str, rival: str) -> dict[str, Any]:
    """One split's items ``featured`` gets right and ``rival`` wrong and the reverse, summed over
    its trainings (a template's one "training" faces each of the network's), and their p-value."""
    theirs = one.correct[rival]
    pairs = [(a, theirs[k % len(theirs)]) for k, a in enumerate(one.correct[featured])]
    ours, others = int(sum((a & ~b).sum() for a, b in pairs)), int(sum((~a & b).sum() for a, b in pairs))
    return {"nasm_only": ours, "baseline_only": others, "p_value": float(mcnemar_exact(ours, others))}


def _by_split(runs: list[SplitRun], config: KittingConfig) -> dict[str, dict[str, dict[str, Any]]]:
    """Each split's mean over its trainings of every method's headline numbers."""
    delta = str(config.headline_delta_s)
    out = {}
    for one in runs:
        means = {name: across(v)[0] for name, v in one.per_training.items()}
        out[str(one.split.seed)] = {m.name: {"auroc": means[m.name]["auroc"][delta],
                                             "detected_1pct": means[m.name]["detected_1pct"],
                                             "normal_flagged_1pct": means[m.name]["normal_flagged_1pct"]}
                                    for m in METHODS}
    return out


def run(config: KittingConfig) -> KittingResult:
    start = time.perf_counter()
    segs = read_segments(config.data)
    alone = config.parallel.workers == 1 or len(config.split_seeds) == 1  # one process: its trainings' bar
    runs = config.parallel.map(run_split, [(segs, replace(config, split_seed=k), alone) for k in config.split_seeds],
                               desc="kitting: splits", unit="split", progress=not alone)
    pooled = {name: [m for one in runs for m in one.per_training[name]] for name in INFO}
    own = {name: [m for one in runs for m in one.own_training[name]] for name in INFO}
    counts = across([one.counts for one in runs])[0]  # the mean over the splits; each split's in by_split
    counts["n_normal_train"] = {s: min(one.counts["n_normal_train"][s] for one in runs) for s in counts["n_normal_train"]}
    counts["by_split"] = {str(one.split.seed): one.counts for one in runs}
    methods = {}
    for m in METHODS:
        mean, spread = across(pooled[m.name])
        methods[m.name] = {"is_neural_asm": m.is_neural_asm, "told_skill": m.told_skill, "label": m.label,
                           "trainings": len(pooled[m.name]), **mean, "range": spread,
                           "anomalies_from_test_runs": _own_runs(across(own[m.name])[0], config)}
        for s, row in methods[m.name]["per_skill"].items():
            row["n_normal_train"] = counts["n_normal_train"].get(s, 0)
    few = {name: [f for one in runs for f in one.few_training.get(name, [])] for name in ("nasm_one", "template_told")}
    path = config.out / "kitting_model.safetensors"
    checkpoint.save(runs[0].memories[0], path)  # the skill memory, as its public SkillMemory.save writes it
    delta = str(config.headline_delta_s)
    first = runs[0].split
    result = KittingResult(
        config={"network": config.network.to_dict(), "trainings": config.trainings, "seeds": list(config.seeds),
                "split_seed": config.split_seed, "splits": list(config.split_seeds), "deltas_s": list(config.deltas_s),
                "recall_mode": config.recall_mode, "fprs": list(config.fprs), "lstm_epochs": config.lstm_epochs,
                "threshold_folds": config.threshold_folds},
        split={"train": list(first.train), "calibration": list(first.calibration), "test": list(first.test),
               "seed": first.seed, "seeds": list(config.split_seeds),
               "by_split": {str(one.split.seed): {"train": list(one.split.train),
                                                  "calibration": list(one.split.calibration),
                                                  "test": list(one.split.test)} for one in runs}},
        counts=counts, methods=methods, few={name: {"trainings": len(v), **across(v)[0]} for name, v in few.items() if v},
        paired=_paired(runs, methods, "skill_memory", delta),
        whole_runs={}, timeline=runs[0].timeline, seconds=0.0, model_path=str(path),
        paired_told=_paired(runs, methods, "skill_memory_told", delta), by_split=_by_split(runs, config),
        paired_cross_fitted=_paired(runs, methods, "skill_memory", delta, cross_fitted=True),
        paired_told_cross_fitted=_paired(runs, methods, "skill_memory_told", delta, cross_fitted=True))
    if config.whole_runs:
        from neural_asm.experiments.kitting.whole_runs import WELL_DEMONSTRATED, score_whole_runs

        demonstrated = [tuple(s for s, n in one.counts["n_normal_train"].items() if n >= WELL_DEMONSTRATED) for one in runs]
        result.whole_runs = score_whole_runs(config, [(one.split, one.memories, d) for one, d in zip(runs, demonstrated)])
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


WHOLE_RUN_KEYS = ("n_runs", "n_anomalies", "n_clean_phases", "flagged_within_1s", "flagged_early",
                  "clean_phases_flagged", "skill_recognised", "skill_recognised_demonstrated")
PAIRED_KEYS = ("baseline", "nasm_only", "baseline_only", "p_value", "by_split")


def headline(result: KittingResult, config: KittingConfig) -> dict[str, Any]:
    """The skill memory not told the skill featured, and told beside it; every method pooled over
    the splits' trainings, and each split's headline numbers in ``by_split``."""
    keys = ("is_neural_asm", "told_skill", "trainings", "auroc", "per_skill", "per_type", "detected_1pct",
            "normal_flagged_1pct", "delay_ms_median", "delay_ms_p95")
    runs = result.whole_runs
    return {"task": "kitting", "featured": "skill_memory", "featured_told": "skill_memory_told",
            "splits": list(config.split_seeds), "deltas_s": list(config.deltas_s),
            "methods": {name: {k: m[k] for k in keys} for name, m in result.methods.items()},
            "by_split": result.by_split,
            "paired": {k: result.paired[k] for k in PAIRED_KEYS},
            "paired_told": {k: result.paired_told[k] for k in PAIRED_KEYS},
            "paired_cross_fitted": {k: result.paired_cross_fitted[k] for k in PAIRED_KEYS},
            "paired_told_cross_fitted": {k: result.paired_told_cross_fitted[k] for k in PAIRED_KEYS},
            "anomalies_from_test_runs": {name: m["anomalies_from_test_runs"] for name, m in result.methods.items()},
            "whole_runs": {k: runs.get("not_told", {}).get(k) for k in WHOLE_RUN_KEYS},
            "whole_runs_told": {k: runs.get("told", {}).get(k) for k in WHOLE_RUN_KEYS},
            "published": PUBLISHED}
