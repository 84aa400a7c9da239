"""Round 4 (docs/kitting.md, "Round 4", hypothesis and rule written there before this ran): told,
one split-conformal threshold from every skill's pooled peaks against a skill's own where it has
>= 99 pooled peaks (the rule `SkillMemory.calibrate` served until then).

Both rules threshold the same told energies of the same memory (the skill memory's defaults,
cross-fitted with five folds by run, networks cached by `lab.kitting_skills`), three trainings
per split; beside them the told template at the same pooled rule (`template_told_cross_fitted`)
and the exact McNemar test of each rule against it.

    python -m lab.kitting_told_threshold "$SCHEME" --splits 6 --splits 7 --splits 8 --cache DIR
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import typer

from lab.kitting_probe import setup
from lab.kitting_skills import metrics, out_of_fold, skill_memory, template_told
from neural_asm.experiments.kitting.config import KittingConfig
from neural_asm.experiments.kitting.methods import Scored, score_template_told_cross_fitted
from neural_asm.models.calibration import conformal_episode_threshold
from neural_asm.models.conformal import mcnemar_exact
from neural_asm.models.skill_calibration import SkillScoring
from neural_asm.models.skill_context import OutOfFold, SkillMemory

RULES = ("a skill's own from 99 peaks", "pooled")


def told_pool(memory: SkillMemory, sets, folds: OutOfFold, scoring: SkillScoring) -> np.ndarray:
    """The told peaks `SkillMemory.calibrate` pools: the threshold segments' under the memory, and
    each fold's training segments' under the fold memory that did not learn them."""
    pool = [memory._episode_energies(memory._spreads(sets.precision.data, sets.precision.skills, scoring),
                                     sets.threshold.data, sets.threshold.skills, sets.threshold.lengths).told]
    for k, fold_memory in enumerate(folds.memories):
        out = folds.fold == k
        cal = fold_memory._spreads(sets.precision.data, sets.precision.skills, scoring)
        pool.append(fold_memory._episode_energies(cal, folds.demonstrations[out], folds.labels[out], folds.lengths[out]).told)
    return np.concatenate(pool)


def one_split(config: KittingConfig, cache: Path) -> dict[str, list[dict]]:
    config, _, _, sets, w = setup(config)
    scoring = SkillScoring()
    rows: dict[str, list[dict]] = {rule: [] for rule in RULES}
    n = len(sets.test)
    for seed in config.seeds:
        memory = skill_memory(sets, config, seed, cache)
        folds = out_of_fold(memory, sets, config, seed, cache, True)
        cal = memory.calibrate(sets.precision.data, sets.precision.skills, sets.threshold.data, sets.threshold.skills,
                               sets.threshold.lengths, scoring, config.fprs, cross_fit=folds)
        told, _ = memory.score(sets.test.data, told=sets.test.skills)
        index = np.array([memory.index(s) for s in sets.test.skills])
        pool = told_pool(memory, sets, folds, scoring)
        rows[RULES[0]].append(metrics(Scored(told, {f: cal.told[f][index] for f in config.fprs}), sets, w, config))
        rows[RULES[1]].append(metrics(Scored(told, {f: np.full(n, conformal_episode_threshold(pool, f))
                                                    for f in config.fprs}), sets, w, config))
        print(f"split {config.split_seed} seed {seed}: own thresholds {np.round(cal.told[0.01], 0)}, pooled "
              f"{conformal_episode_threshold(pool, 0.01):.0f} of {len(pool)} peaks", flush=True)
    rival = score_template_told_cross_fitted(template_told(sets, config), sets, config, 0)
    rows["template_told_cross_fitted"] = [metrics(rival, sets, w, config)]
    return rows


def summary(by_split: dict[int, dict[str, list[dict]]]) -> str:
    lines = ["| split | told, threshold | mean AUROC 3-5 | detected 1 % | normal flagged 1 % | delay median (ms) | "
             "against template_told_cross_fitted: memory only / rival only (summed), p | per training |",
             "|---|---|---|---|---|---|---|---|"]
    for split, rows in by_split.items():
        (b,) = [r["correct"] for r in rows["template_told_cross_fitted"]]
        for name, runs in rows.items():
            cells = [f"{np.mean([r[k] for r in runs]):.3f} ({np.min([r[k] for r in runs]):.3f}-"
                     f"{np.max([r[k] for r in runs]):.3f})" for k in ("auroc", "detected", "normal_flagged")]
            delay = f"{np.nanmean([r['delay_ms'] for r in runs]):.0f}"
            a_only = [int((r["correct"] & ~b).sum()) for r in runs]
            b_only = [int((~r["correct"] & b).sum()) for r in runs]
            paired = (f"{sum(a_only)} / {sum(b_only)}, p = {mcnemar_exact(sum(a_only), sum(b_only)):.2g}"
                      if name in RULES else "–")
            each = ", ".join(f"{x}/{y}" for x, y in zip(a_only, b_only)) if name in RULES else "–"
            lines.append(f"| {split} | {name} | " + " | ".join(cells) + f" | {delay} | {paired} | {each} |")
    return "\n".join(lines)


def main(data: Path = typer.Argument(..., help="the clone's 'No.0 filtering scheme' folder"),
         splits: list[int] = typer.Option([6, 7, 8]), seeds: int = typer.Option(3, min=1),
         cache: Path = typer.Option(Path("kitting_skills_cache"), help="trained networks, per split and seed"),
         out: Path | None = typer.Option(None, help="also write the table here")) -> None:
    by_split = {}
    for split in splits:
        config = KittingConfig(data=data, out=cache, trainings=seeds, split_seed=split)
        by_split[split] = one_split(config, cache / f"split{split}")
        print(summary({split: by_split[split]}), flush=True)
    text = summary(by_split)
    print(text)
    if out is not None:
        out.write_text(text + "\n")


if __name__ == "__main__":
    typer.run(main)
