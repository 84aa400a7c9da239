"""Why does the one network let skill 5's ``no_object`` pass as another skill's normal? A probe
beside the kitting benchmark (docs/kitting.md, "One memory for every skill"), on the benchmark's
own split, windows, networks (three trainings) and calibration:

1. **The cue**: which skill the served plan memory's cue regression (`models.plan`) and the
   served recognition by mean errors (`Calibration.recognised`) name for the ``no_object``
   segments, and their tactile spread at the cue beside skill 5's normal ones.
2. **Variants of the served rule** on the network's errors, offline and online: the skill
   recognised at every step (served), recognised from the first k steps and held, or told
   (`Calibration.centre(told=...)`, the oracle); one episode threshold, or one per recognised
   skill (split-conformal on that skill's threshold segments; the pooled one for a skill with
   fewer than ``MIN_SKILL_EPISODES``). Ranked by each window's peak of energy over its threshold.
3. **Whether the data allow it without the skill**: a z-score template of every skill picking
   the skill whose template explains the steps so far best, with one spread for every skill
   (pooled) or each skill's own (the skill picked by likelihood).

    python -m lab.kitting_probe "$SCHEME" [--seeds 3]
"""

from __future__ import annotations

from collections import Counter
from pathlib import Path

import numpy as np
import typer

from neural_asm.experiments.kitting.config import KittingConfig
from neural_asm.experiments.kitting.data import read_segments, split_runs
from neural_asm.experiments.kitting.methods import Scored, Sets, calibrate_served, fit_network, served_thresholds
from neural_asm.experiments.kitting.metrics import Windows, method_metrics, windows
from neural_asm.experiments.kitting.run import make_sets
from neural_asm.models.asm import NeuralASM
from neural_asm.models.calibration import Calibration, conformal_episode_threshold
from neural_asm.models.normaliser import Normaliser
from neural_asm.models.scoring import quadratic, step_rows

TACTILE = [4, 5]
MIN_SKILL_EPISODES = 5
HELD = (1, 20)  # steps the skill is recognised from before it is held


def picks(cal: Calibration, errors: np.ndarray, segs, recognition: str, k: int) -> np.ndarray:
    """(N, T) the skill (index; -1 the skills' average) whose mean errors centre each step."""
    steps = errors.shape[1]
    if recognition == "told":
        told = [cal.skills.index(s) if s in cal.skills else -1 for s in segs.skills]
        return np.repeat(np.array(told)[:, None], steps, axis=1)
    pick = cal.recognised(errors)
    if recognition == "held":
        pick = np.where(np.arange(steps)[None] <= k, pick, pick[:, [min(k, steps - 1)]])
    return pick


def energies(cal: Calibration, errors: np.ndarray, pick: np.ndarray) -> np.ndarray:
    steps = errors.shape[1]
    centred = errors - cal._means_at(np.arange(steps))[pick, np.arange(steps)]
    return quadratic(centred / step_rows(cal.error_std, steps), step_rows(cal.error_precision, steps))


def variant(model: NeuralASM, sets: Sets, w: Windows, config: KittingConfig, mode: str, recognition: str, k: int,
            per_skill: bool) -> dict[str, float]:
    cal = calibrate_served(model, sets, mode, True, config.fprs)
    scored = {}
    for name in ("threshold", "test"):
        segs = getattr(sets, name)
        errors = model.errors(segs.data, mode).astype(np.float64)
        pick = picks(cal, errors, segs, recognition, k)
        scored[name] = (energies(cal, errors, pick), pick)
    (e_th, _), (e_te, pick_te) = scored["threshold"], scored["test"]
    pooled = served_thresholds(e_th, sets.threshold.lengths, (0.01,))[0.01]
    table = np.full(len(cal.skills) + 1, pooled)
    if per_skill:
        for j, s in enumerate(cal.skills):
            rows = sets.threshold.skills == s
            if rows.sum() >= MIN_SKILL_EPISODES:
                table[j] = conformal_episode_threshold(
                    np.array([e[:n].max() for e, n in zip(e_th[rows], sets.threshold.lengths[rows])]), 0.01)
    relative = e_te / table[pick_te]  # the served decision: a step's energy above its threshold
    m, _ = method_metrics(Scored(relative, {f: np.ones(len(sets.test)) for f in config.fprs}), sets.test, w, config,
                          config.headline_skills)
    return {"auroc": m["auroc"]["0.5"], "skill_5": m["per_skill"]["5"]["auroc"]["0.5"],
            "no_object": m["per_type"]["no_object"]["auroc_0.5"], "detected": m["detected_1pct"],
            "normal_flagged": m["normal_flagged_1pct"]}


def templates(sets: Sets, w: Windows, config: KittingConfig) -> dict[str, dict[str, float]]:
    """The z-score template of every skill, not told the skill, with pooled or per-skill spreads."""
    norm = Normaliser.fit(sets.train.data)
    skills = sorted(set(sets.train.skills))
    means = np.stack([norm.normalise(sets.train.data[sets.train.skills == s]).mean(0) for s in skills])
    x_p = norm.normalise(sets.precision.data)
    residual = x_p - means[[skills.index(s) for s in sets.precision.skills]]
    pooled = np.sqrt((residual ** 2).mean(0))
    own = np.stack([np.sqrt(((residual[sets.precision.skills == s] ** 2).sum(0) + 2 * pooled ** 2)
                            / ((sets.precision.skills == s).sum() + 2)) for s in skills])  # shrunk to the pooled
    out = {}
    for name, spread, likelihood in (("pooled spreads", np.broadcast_to(pooled, means.shape), False),
                                     ("each skill's spreads, by likelihood", own, True)):
        def energy(x: np.ndarray) -> np.ndarray:
            z = ((norm.normalise(x)[:, None] - means[None]) / spread[None]) ** 2  # (N, S, T, D)
            e = z.sum(-1)
            fit = e + (2 * np.log(spread).sum(-1)[None] if likelihood else 0)
            before = np.concatenate([fit[..., :1], np.cumsum(fit, 2)[..., :-1]], 2)
            return np.take_along_axis(e, before.argmin(1)[:, None], 1)[:, 0]

        thresholds = served_thresholds(energy(sets.threshold.data), sets.threshold.lengths, config.fprs)
        scored = Scored(energy(sets.test.data), {f: np.full(len(sets.test), t) for f, t in thresholds.items()})
        m, _ = method_metrics(scored, sets.test, w, config, config.headline_skills)
        out[name] = {"auroc": m["auroc"]["0.5"], "skill_5": m["per_skill"]["5"]["auroc"]["0.5"],
                     "no_object": m["per_type"]["no_object"]["auroc_0.5"]}
    return out


def cue(model: NeuralASM, sets: Sets) -> dict[str, object]:
    test = sets.test
    rows = test.anomalies == "no_object"
    x0 = model.normaliser.normalise(test.data[rows, 0])
    plan = Counter(model.plan.skills[i] for i in model.plan.recognise(x0)) if model.plan else {}
    cal = calibrate_served(model, sets, "offline", True, (0.01,))
    served = Counter(cal.skills[i] for i in cal.recognised(model.errors(test.data[rows], "offline"))[:, 60])
    normal5 = test.normal & (test.skills == "5")
    return {"no_object": int(rows.sum()), "plan cue regression names": dict(plan),
            "served recognition at step 60 names": dict(served),
            "tactile spread at the cue, no_object": float(test.data[rows, 0][:, TACTILE].mean()),
            "tactile spread at the cue, skill 5 normal": float(test.data[normal5, 0][:, TACTILE].mean()),
            "tactile spread at the cue, skills 3-4 normal": float(
                test.data[test.normal & np.isin(test.skills, ["3", "4"]), 0][:, TACTILE].mean())}


def main(data: Path = typer.Argument(..., help="the clone's 'No.0 filtering scheme' folder"),
         seeds: int = typer.Option(3, min=1)) -> None:
    config = KittingConfig(data=data, out=Path("."), trainings=seeds)
    segs = read_segments(data)
    sets = make_sets(segs, split_runs(segs.runs, config.train_fraction, config.split_seed))
    w = windows(sets.test, config, config.headline_skills)
    rows: dict[str, list[dict[str, float]]] = {}
    for seed in config.seeds:
        model = fit_network(sets.train, config, seed)
        if seed == 0:
            print(cue(model, sets))
        for mode in ("offline", "online"):
            for recognition, ks in (("every step", (0,)), ("held", HELD), ("told", (0,))):
                for k in ks:
                    for per_skill in (False, True):
                        how = {"every step": "recognised at every step (served)",
                               "held": f"recognised from the first {k} step(s), then held",
                               "told": "told (oracle)"}[recognition]
                        name = f"{mode}, skill {how}, {'per-skill' if per_skill else 'one'} threshold"
                        rows.setdefault(name, []).append(variant(model, sets, w, config, mode, recognition, k, per_skill))
    keys = list(next(iter(rows.values()))[0])
    print("| variant | " + " | ".join(keys) + " |\n|---|" + "---|" * len(keys))
    for name, runs in rows.items():
        cells = [f"{np.mean([r[k] for r in runs]):.2f} ({min(r[k] for r in runs):.2f}-{max(r[k] for r in runs):.2f})"
                 for k in runs[0]]
        print(f"| {name} | " + " | ".join(cells) + " |")
    for name, m in templates(sets, w, config).items():
        print(f"template of every skill, not told, {name}: " + ", ".join(f"{k} {v:.2f}" for k, v in m.items()))


if __name__ == "__main__":
    typer.run(main)
