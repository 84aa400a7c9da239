"""Score every method on the same episodes with the same thresholds.

Per method: normalised errors on every set; per-step spreads and precision matrices from the
precision split (the service's own `estimate`), whitened energies; an episode's score is its
peak energy (for a fault, from its onset on). Thresholds come from the calibration split at
`alpha`: the episode threshold is the one a checkpoint stores and the service applies
(`models.calibration.Thresholds`: the peak energy that a share `alpha` of normal episodes
exceed; at the benchmark's 300 calibration episodes and 1 % it is the split-conformal rank);
the time-varying one (per-step scales from the precision split) is split-conformal.
A fault is detected when its energy crosses the threshold at or after its onset.

With validation faults in the benchmark and two baselines or more, one more rival is scored
alike: the best pair of baselines flagging when either does, chosen on the validation faults
(experiments/varied/pairs.py). Only the baselines' energies of the validation faults are
computed, and only that choice reads them.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from sklearn.metrics import roc_auc_score
from tqdm.auto import tqdm

from experiments.varied.data import VariedBenchmark
from experiments.methods import Method
from models.calibration import Thresholds, estimate
from models.config import SCORING
from models.conformal import TimeVaryingThreshold, binomial_interval, mcnemar_exact
from models.normaliser import Normaliser
from sim.config import SIM
from sim.varied import channel_groups

ALPHA = SCORING.default_fpr  # the episode false-alarm rate every method is held to
SETS = ("precision", "calibration", "test", "ood", "faults")
VALIDATION = "val_faults"  # the validation faults' energies: read by the pair's choice only
PAIR = "best_pair"  # the either-of-two rival's name


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


def energies(method: Method, bench: VariedBenchmark, norm: Normaliser, validation: bool = False
             ) -> tuple[dict[str, np.ndarray], dict]:
    """Whitened energies (N, T) of every set (with `validation`, of the validation faults too,
    under `VALIDATION`) under the method's own precisions, and the method's held-out error on
    the precision split (how well it expects held-out normal episodes, before any weighting)."""
    errors = {}
    for key in (SETS + (VALIDATION,)) if validation else SETS:
        arrays = bench.validation.faults if key == VALIDATION else getattr(bench, key)
        x = norm.normalise(arrays.data)
        errors[key] = x - method.expected(x, arrays.labels)
    cal = estimate("varied", 1, errors["precision"], "precision split", "full")
    return {key: cal.energy(e) for key, e in errors.items()}, held_out_error(
        errors["precision"], bench.channel_names)


def held_out_error(errors: np.ndarray, channel_names: tuple[str, ...]) -> dict:
    """Mean squared normalised error after the first step, overall and per kind of channel."""
    squared = errors[:, 1:].astype(np.float64) ** 2
    return {"all": float(squared.mean()),
            **{group: float(squared[..., cols].mean()) for group, cols in channel_groups(channel_names).items()}}


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


def score_all(bench: VariedBenchmark, methods: list[Method], norm: Normaliser, alpha: float = ALPHA
              ) -> tuple[dict, dict]:
    """Summaries {method: {rule: summary}} and outcomes {(method, rule): Outcome}; with
    validation faults and two baselines or more, the either-of-two rival `PAIR` too."""
    summaries, results, rivals = {}, {}, {}
    pair = bench.validation is not None and sum(not m.is_neural_asm for m in methods) >= 2
    for method in tqdm(methods, desc="scoring"):
        e, held_out = energies(method, bench, norm, validation=pair and not method.is_neural_asm)
        if VALIDATION in e:
            rivals[method.name] = e
        rules = outcomes(e, bench.onset, alpha)
        summaries[method.name] = {"label": method.label, "is_neural_asm": method.is_neural_asm,
                                  "held_out_mse": held_out["all"], "held_out_mse_per_group": held_out,
                                  **{rule: summary(o, bench) for rule, o in rules.items()}}
        results.update({(method.name, rule): o for rule, o in rules.items()})
    if pair:
        from experiments.varied.pairs import best_pair  # it builds on this module's outcomes() and summary()

        summaries[PAIR], rules = best_pair(rivals, {m.name: m for m in methods}, bench, alpha)
        results.update({(PAIR, rule): o for rule, o in rules.items()})
    return summaries, results


def _share(rate: float | None, oracle: float | None) -> float | None:
    return None if rate is None or not oracle else rate / oracle


def _paired(results: dict, featured: str, best: str, rows: np.ndarray) -> dict:
    """Exact McNemar test of the featured method against ``best`` on the faults ``rows``."""
    ours, theirs = results[(featured, "episode")].detected[rows], results[(best, "episode")].detected[rows]
    nasm_only, baseline_only = int((ours & ~theirs).sum()), int((~ours & theirs).sum())
    return {"baseline": best, "nasm_only": nasm_only, "baseline_only": baseline_only,
            "p_value": mcnemar_exact(nasm_only, baseline_only)}


def headline(summaries: dict, results: dict, bench: VariedBenchmark, featured: str, alpha: float = ALPHA,
             oracle: dict | None = None) -> dict:
    """The contract's headline: the featured Neural ASM, every method, each rate beside the
    oracle's (``oracle``: its ``visible`` and ``consequential`` detection, None when not scored),
    and exact McNemar tests against the best other method, on visible and on consequential faults.
    The either-of-two rival, when scored, is one of the other methods; its choice is under "or_pair"."""
    rule = "episode"
    oracle = oracle or {}
    methods = {name: {"is_neural_asm": s["is_neural_asm"], **{k: s[rule][k] for k in (
        "detection", "normal_episode_false_alarm", "benign_ood_false_alarm", "auroc", "median_delay_steps")},
        "oracle_share": _share(s[rule]["detection"], oracle.get("visible"))}
        for name, s in summaries.items()}
    rivals = [n for n, s in summaries.items() if not s["is_neural_asm"]]
    best = max(rivals, key=lambda n: summaries[n][rule]["detection"])
    consequences = {name: s[rule]["consequential"] for name, s in summaries.items()}
    best_consequential = max(rivals, key=lambda n: consequences[n]["detection"] or 0.0)
    choice = {"or_pair": summaries[PAIR]["or_pair"]} if PAIR in summaries else {}
    return {"featured": featured, "episode_fa_target": alpha, "methods": methods,
            "paired": _paired(results, featured, best, bench.visible),
            "per_family": {name: {family: f["detection_visible"] for family, f in s[rule]["per_family"].items()}
                           for name, s in summaries.items()},
            "consequential": {
                "featured": featured, "n": int((bench.consequence == "consequential").sum()),
                "oracle_detection": oracle.get("consequential"),
                "methods": {name: {"is_neural_asm": summaries[name]["is_neural_asm"], "detection": c["detection"],
                                   "oracle_share": _share(c["detection"], oracle.get("consequential")),
                                   "lead_time_s_median": c["lead_time_s_median"],
                                   "normal_episode_false_alarm": summaries[name][rule]["normal_episode_false_alarm"],
                                   "benign_ood_false_alarm": c["benign_ood_false_alarm"], "auroc": c["auroc"]}
                            for name, c in consequences.items()},
                "paired": _paired(results, featured, best_consequential, bench.consequence == "consequential")},
            **choice}
