"""The either-of-two rival: the best OR-combination of two baselines, chosen on validation faults.

Complementary detectors can be combined by flagging when either does (as Sentinel pairs its
two). Every unordered pair (A, B) of baselines gets the per-step energy
``c_t = max(e_A,t / s_A, e_B,t / s_B)``, where ``s_M`` is M's own served episode threshold on the
precision split: a relative scale only, putting both members' energies in units of what each
would flag. The combined energies then go through the benchmark's own `outcomes()`, so the pair
is held to the served episode threshold on the calibration split's combined energies, like
every method. The pair kept detects the most visible validation faults at that threshold;
ties go to the higher AUROC of the visible validation faults against the calibration split's
normal episodes (not the precision split's: the scales are set on its peaks, at 150 episodes and
1 % its largest, so its combined peaks are at most 1 by construction), then to the first pair in
the baselines' order. The test faults play no part in the choice; the validation faults no part in any
threshold.
"""

from __future__ import annotations

from itertools import combinations

import numpy as np
from sklearn.metrics import roc_auc_score

from neural_asm.experiments.methods import Method
from neural_asm.experiments.varied.data import FaultSet, VariedBenchmark
from neural_asm.experiments.varied.outcomes import ALPHA, VALIDATION, Outcome, after_onset, outcomes, summary
from neural_asm.models.calibration import Thresholds

PAIR = "best_pair"  # the either-of-two rival's name
Energies = dict[str, np.ndarray]  # set -> (N, T) whitened energies
TIE_BREAK = ("validation detection, then AUROC of visible validation faults against calibration-split normals, "
             "then baseline order")


def scale(e: Energies, alpha: float = ALPHA) -> float:
    """A method's served episode threshold on the precision split: its energies' unit in a pair."""
    return Thresholds.of(e["precision"], alpha).episode


def combined(a: Energies, b: Energies, alpha: float = ALPHA) -> Energies:
    """``max(e_A / s_A, e_B / s_B)`` on every set both have: above t exactly when A is above
    t s_A or B above t s_B."""
    sa, sb = scale(a, alpha), scale(b, alpha)
    return {key: np.maximum(a[key] / sa, b[key] / sb) for key in a.keys() & b.keys()}


def validation_scores(c: Energies, validation: FaultSet, alpha: float = ALPHA) -> tuple[float, float]:
    """Detection of the visible validation faults by the benchmark's own episode rule (outcomes()
    with the validation faults in the test faults' place), and their AUROC against the calibration
    split's normal episodes (peak energy from the onset on against peak energy)."""
    visible = validation.visible
    if not visible.any():
        raise ValueError("no visible validation fault: nothing to choose a pair on")
    o = outcomes({**c, "faults": c[VALIDATION]}, validation.onset, alpha)["episode"]
    peaks = after_onset(c[VALIDATION], validation.onset).max(axis=1)[visible]
    normal = c["calibration"].max(axis=1)
    auroc = roc_auc_score(np.r_[np.ones(len(peaks)), np.zeros(len(normal))], np.r_[peaks, normal])
    return float(o.detected[visible].mean()), float(auroc)


def choose(rivals: dict[str, Energies], validation: FaultSet, alpha: float = ALPHA) -> tuple[tuple[str, str], dict]:
    """The pair of rivals (in their given order) whose combination does best on the visible
    validation faults, and a record of the choice: every pair's validation detection and AUROC,
    each rival's own validation detection (what a pair adds), the pairs tied on detection with
    the chosen one, the members' scales. Reads the rivals' precision, calibration and validation
    energies only."""
    scores = {(a, b): validation_scores(combined(rivals[a], rivals[b], alpha), validation, alpha)
              for a, b in combinations(rivals, 2)}
    best = max(scores, key=lambda pair: scores[pair])  # max keeps the first of equals
    return best, {"chosen": list(best), "scales": {name: scale(rivals[name], alpha) for name in best},
                  "validation_faults": len(validation.visible), "validation_visible": int(validation.visible.sum()),
                  "validation_detection": {f"{a} | {b}": d for (a, b), (d, _) in scores.items()},
                  "validation_auroc": {f"{a} | {b}": auroc for (a, b), (_, auroc) in scores.items()},
                  "validation_detection_alone": {name: validation_scores(e, validation, alpha)[0]
                                                 for name, e in rivals.items()},
                  "tied_on_detection": [f"{a} | {b}" for (a, b), (d, _) in scores.items() if d == scores[best][0]],
                  "tie_break": TIE_BREAK}


def best_pair(rivals: dict[str, Energies], methods: dict[str, Method], bench: VariedBenchmark, alpha: float = ALPHA
              ) -> tuple[dict, dict[str, Outcome]]:
    """The chosen pair as one more rival: its summary entry (with the choice's record under
    "or_pair") and its outcomes, both from the benchmark's own `outcomes()` and `summary()`."""
    if bench.validation is None:
        raise ValueError("the benchmark has no validation faults to choose a pair on")
    (a, b), record = choose(rivals, bench.validation, alpha)
    rules = outcomes(combined(rivals[a], rivals[b], alpha), bench.onset, alpha)
    entry = {"label": "either of two rivals, chosen on validation faults",  # which two: in "or_pair"
             "is_neural_asm": False, "held_out_mse": None, "held_out_mse_per_group": None, "or_pair": record,
             **{rule: summary(o, bench) for rule, o in rules.items()}}
    return entry, rules


__all__ = ["PAIR", "best_pair", "choose", "combined", "scale", "validation_scores"]
