"""Score every method on the same episodes with the same thresholds.

Per method: normalised errors on every set; per-step spreads and precision matrices from the
precision split (the service's own `estimate`), whitened energies; an episode's score is its
peak energy (for a fault, from its onset on), turned into flags and rates by
`experiments.varied.outcomes`.

With validation faults in the benchmark, every method's share of them flagged is reported (what
the featured recall mode and the ablation's variants are chosen by), and with two baselines or
more one more rival is scored alike: the best pair of baselines flagging when either does, chosen
on the validation faults (experiments/varied/pairs.py).
"""

from __future__ import annotations

import numpy as np
from tqdm.auto import tqdm

from neural_asm.experiments.varied.data import VariedBenchmark
from neural_asm.experiments.methods import Method
from neural_asm.experiments.varied.outcomes import ALPHA, VALIDATION, outcomes, summary
from neural_asm.experiments.varied.pairs import PAIR, best_pair, validation_scores
from neural_asm.models.calibration import estimate
from neural_asm.models.conformal import mcnemar_exact
from neural_asm.models.normaliser import Normaliser
from neural_asm.sim.varied import channel_groups

SETS = ("precision", "calibration", "test", "ood", "faults")


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


def score_all(bench: VariedBenchmark, methods: list[Method], norm: Normaliser, alpha: float = ALPHA
              ) -> tuple[dict, dict]:
    """Summaries {method: {rule: summary}} and outcomes {(method, rule): Outcome}; with
    validation faults and two baselines or more, the either-of-two rival `PAIR` too."""
    summaries, results, rivals = {}, {}, {}
    validation = bench.validation is not None
    pair = validation and sum(not m.is_neural_asm for m in methods) >= 2
    for method in tqdm(methods, desc="scoring"):
        e, held_out = energies(method, bench, norm, validation=validation)
        if pair and not method.is_neural_asm:
            rivals[method.name] = e
        rules = outcomes(e, bench.onset, alpha)
        summaries[method.name] = {"label": method.label, "is_neural_asm": method.is_neural_asm,
                                  "held_out_mse": held_out["all"], "held_out_mse_per_group": held_out,
                                  # a selection number that counts faults, not one-step error
                                  "validation_fault_detection": validation_scores(e, bench.validation, alpha)[0]
                                  if validation else None,
                                  **{rule: summary(o, bench) for rule, o in rules.items()}}
        results.update({(method.name, rule): o for rule, o in rules.items()})
    if pair:
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
