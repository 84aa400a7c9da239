"""One memory that knows each skill's course, told the skill or inferring it (docs/kitting.md, "A
memory that knows each skill's course"). Written before it was run.

Hypothesis: one network for every skill, told the skill by a one-hot cue (observed and fed to the
prior as the context input W_C c), scored by a course term (the skill's offline recall from its
own start) and a dynamics term (online recall under the skill's cue), each whitened by the skill's
own spreads per step (`models.skill_context`), with, not told, a posterior over the skills updated
every step (forgetting 0.01) and the fault energy the step's surprise under the skills still
plausible (`models.skill_posterior`), reaches on every run-wise split 0-2 (three trainings each,
delta 0.5 s, the benchmark's protocol and code): not told mean AUROC over skills 3-5 >= 0.97 with
no_object >= 0.90; told >= 0.98; >= 85 % detected and <= 2 % of normal test segments flagged at
the served 1 % threshold; median delay <= 100 ms. Adopted if all hold on every split.

Rows, not told and told: the memory (course + dynamics: the primary), its course alone, its
dynamics alone, the demonstrations' mean course with its dynamics (what the network's course adds
over a template); beside them template_likelihood (each skill's mean course and own spreads, the
most probable skill step by step), template_told, nasm_one and nasm_one_online.

Confounds: the no_object day, anomalies of every run, the 1 % threshold on 36-40 peaks, the silent
tactile pad, per-skill spreads from 7-14 segments; ε and the shrinkage fixed before any run.

    python -m lab.kitting_skills "$SCHEME" --splits 0 --splits 1 --splits 2 --seeds 3 [--cache DIR] [--only TEXT]

Variants added after runs are marked where VARIANTS lists them. The answer (docs/kitting.md): the
hypothesis is wrong; the network's recalled course drifts, and forgetting lets a failing run be
re-explained by another skill.

Round 2 (docs/kitting.md, "Round 2", each hypothesis and rule written there before its run): the
rows named "r2: ...": thresholds cross-fitted from fold memories trained without each of `FOLDS`
folds of the training runs (cached beside the networks), a Student-t dynamics term, the most
probable skill's energy, and the paired McNemar table; splits 3-5 were first run for H4.

    python -m lab.kitting_skills "$SCHEME" --splits 0 --splits 1 --splits 2 --seeds 3 --cache DIR --only "r2:"
    python -m lab.kitting_skills "$SCHEME" --splits 3 --splits 4 --splits 5 --seeds 3 --cache DIR --only "r2:" --no-benchmark

Round 4's H6 (docs/kitting.md): the rows named "r4: ...", on splits never run before.

    python -m lab.kitting_skills "$SCHEME" --splits 9 --splits 10 --splits 11 --seeds 3 --cache DIR --only "r4:" --no-benchmark

Round 5's H7: the "r5: ..." row beside the served defaults ("r4: served defaults ..."), on splits never run before.

    python -m lab.kitting_skills "$SCHEME" --splits 12 --splits 13 --splits 14 --seeds 3 --cache DIR --only "served defaults" --no-benchmark
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import NamedTuple

import numpy as np
import typer

from lab.kitting_probe import setup
from neural_asm.experiments.kitting.config import KittingConfig
from neural_asm.experiments.kitting.data import COLUMNS, kitting_mapping
from neural_asm.experiments.kitting.methods import (RATE_HZ, Scored, Sets, calibrated_energies, fit_network,
                                                    score_network)
from neural_asm.experiments.kitting.metrics import Windows, method_metrics
from neural_asm.models import checkpoint
from neural_asm.models.asm import NeuralASM
from neural_asm.models.conformal import mcnemar_exact
from neural_asm.models.normaliser import Normaliser
from neural_asm.models.skill_calibration import SkillScoring
from neural_asm.models.skill_context import OutOfFold, SkillMemory, mean_courses
from neural_asm.rivals.templates import PerSkillZScore



class Variant(NamedTuple):
    """A row of the memory: the terms scored, its course (recalled by the network or the
    demonstrations' "mean"), the terms that recognise the skill (none: the scored ones), the rule,
    the forgetting; round 2: the terms held to a Student-t (term, ν), and thresholds cross-fitted;
    round 4: the terms weighed with their channels' correlations; round 5: each skill's energy in its
    own units, not told."""

    terms: tuple[str, ...]
    course: str
    recognised_by: tuple[str, ...] = ()
    rule: str = "surprise"
    forgetting: float = 0.01
    tails: tuple[tuple[str, float], ...] = ()
    cross_fitted: bool = False
    correlated: tuple[str, ...] = ()
    scaled: bool = False


DEFAULTS = Variant(("course", "dynamics"), "mean", ("course",), "surprise", 0.0)
STUDENT = (("dynamics", 4.0),)
VARIANTS = {
    "skill memory (course + dynamics)": (("course", "dynamics"), "recalled", (), "surprise", 0.01),
    "its course alone": (("course",), "recalled", (), "surprise", 0.01),
    "its dynamics alone": (("dynamics",), "recalled", (), "surprise", 0.01),
    "mean course + its dynamics": (("course", "dynamics"), "mean", (), "surprise", 0.01),
    "skill memory, most probable skill's energy": (("course", "dynamics"), "recalled", (), "most_probable", 0.01),
    # written after split 0's first run (not in the hypothesis): the skill recognised by the course alone
    "skill memory, recognised by its course": (("course", "dynamics"), "recalled", ("course",), "surprise", 0.01),
    "mean course + its dynamics, recognised by the course": (("course", "dynamics"), "mean", ("course",), "surprise",
                                                             0.01),
    # written after split 0's second run: what the rule and what the dynamics term cost against the template
    "mean course alone": (("course",), "mean", (), "surprise", 0.01),
    "mean course + its dynamics, the template's rule": (("course", "dynamics"), "mean", ("course",), "most_probable",
                                                        0.0),
    # written after every split's third run: whether the forgetting is what lets no_object pass
    "mean course alone, no forgetting": (("course",), "mean", (), "surprise", 0.0),
    "mean course + its dynamics, recognised by the course, no forgetting": (("course", "dynamics"), "mean", ("course",),
                                                                            "surprise", 0.0),
    # round 2 (docs/kitting.md, "Round 2"), written before its runs: H1 thresholds cross-fitted, H2 a
    # Student-t dynamics term
    "r2: defaults": DEFAULTS,
    "r2: defaults, cross-fitted": DEFAULTS._replace(cross_fitted=True),
    "r2: defaults, Student-t dynamics (ν 4)": DEFAULTS._replace(tails=STUDENT),
    "r2: defaults, Student-t dynamics (ν 4), cross-fitted": DEFAULTS._replace(tails=STUDENT, cross_fitted=True),
    "r2: mean course alone, no forgetting, cross-fitted": Variant(("course",), "mean", (), "surprise", 0.0, (), True),
    # round 2's H3, written after H1 and H2 had run: the most probable skill's energy
    "r2: defaults, most probable skill's energy": DEFAULTS._replace(rule="most_probable"),
    "r2: defaults, most probable skill's energy, cross-fitted": DEFAULTS._replace(rule="most_probable",
                                                                                  cross_fitted=True),
    "r2: defaults, most probable skill's energy, Student-t dynamics (ν 4)": DEFAULTS._replace(rule="most_probable",
                                                                                              tails=STUDENT),
    "r2: defaults, most probable skill's energy, Student-t dynamics (ν 4), cross-fitted": DEFAULTS._replace(
        rule="most_probable", tails=STUDENT, cross_fitted=True),
    # round 4's H6 (docs/kitting.md, "Round 4, H6"), written before its run on splits 9-11: the served
    # defaults, and the same with the course term weighed by per-step precision matrices
    "r4: served defaults, cross-fitted": DEFAULTS._replace(rule="most_probable", tails=STUDENT, cross_fitted=True),
    "r4: served defaults, the course correlated, cross-fitted": DEFAULTS._replace(
        rule="most_probable", tails=STUDENT, cross_fitted=True, correlated=("course",)),
    # round 5's H7 (docs/kitting.md, "Round 5"), written before its run on splits 12-14: the served
    # defaults, not told each step's energy in its skill's own units
    "r5: served defaults, each skill's own units, cross-fitted": DEFAULTS._replace(
        rule="most_probable", tails=STUDENT, cross_fitted=True, scaled=True),
}
# The report's likelihood template: each skill's mean course and own spreads, the most probable skill.
TEMPLATE_LIKELIHOOD = Variant(("course",), "mean", (), "most_probable", 0.0)
# Cross-fitting's folds, the benchmark's (`KittingConfig.threshold_folds`): a fold network trains in ~10 s.
FOLDS = 5
COLUMNS_OUT = ("auroc", "skill_5", "no_object", "detected", "normal_flagged", "delay_ms", "recognised", "no_object_as_5")


def cached(path: Path, fit) -> NeuralASM:
    """A network from ``path``, or trained by ``fit()`` and saved there (whole, or not at all)."""
    if path.exists():
        return checkpoint.load(path)
    model = fit()
    path.parent.mkdir(parents=True, exist_ok=True)
    checkpoint.save(model, path.with_suffix(".part"))
    path.with_suffix(".part").rename(path)
    return model


def skill_memory(sets: Sets, config: KittingConfig, seed: int, cache: Path) -> SkillMemory:
    train = sets.train
    skills = np.array(sorted(set(train.skills.tolist())))
    model = cached(cache / f"seed{seed}_skill.safetensors", lambda: SkillMemory.fit(
        train.data, tuple(COLUMNS), train.skills, config.network.with_(seed=seed, plan_memory=False), rate_hz=RATE_HZ,
        provenance={"benchmark": "kitting", "seed": seed, "mapping": kitting_mapping().to_dict()}).model)
    return SkillMemory(model, mean_courses(train.data, train.skills, skills))


def out_of_fold(memory: SkillMemory, sets: Sets, config: KittingConfig, seed: int, cache: Path,
                network: bool) -> OutOfFold:
    """The training runs cut into `FOLDS` folds by run (the benchmark's deal), each fold's memory
    trained without it and cached (``network``), or this memory's network with the other folds'
    mean courses (enough for the course term)."""
    def fold_memory(k: int, x: np.ndarray, y: np.ndarray) -> SkillMemory:
        if not network:
            return memory.fold(x, y, network=False)
        model = cached(cache / f"seed{seed}_fold{k}of{FOLDS}_skill.safetensors", lambda: memory.fold(x, y).model)
        return SkillMemory(model, memory.fold(x, y, network=False).means)  # a skill the fold lacks keeps its course

    train = sets.train
    return OutOfFold.fit(memory, train.data, train.skills, train.lengths, train.runs, FOLDS, config.split_seed,
                         fold_memory)


def metrics(scored: Scored, sets: Sets, w: Windows, config: KittingConfig) -> dict[str, float]:
    """The table's numbers, and the served decisions each item gets right (``correct``: anomalies
    detected, then normal segments not flagged, at 1 %) for the paired test."""
    m, correct = method_metrics(scored, sets.test, w, config, config.headline_skills)
    return {"auroc": m["auroc"]["0.5"], "skill_5": m["per_skill"]["5"]["auroc"]["0.5"],
            "no_object": m["per_type"]["no_object"]["auroc_0.5"], "detected": m["detected_1pct"],
            "normal_flagged": m["normal_flagged_1pct"], "delay_ms": float("nan") if m["delay_ms_median"] is None else m["delay_ms_median"],
            "per_type": {t: v["auroc_0.5"] for t, v in m["per_type"].items()}, "correct": correct}


def memory_rows(memory: SkillMemory, sets: Sets, w: Windows, config: KittingConfig, variants: dict[str, tuple],
                folds: dict[bool, OutOfFold]) -> dict[str, dict[str, float]]:
    """Each variant's metrics, not told and told the skill (``(told)`` in the row's name); ``folds``:
    the fold memories cross-fitted rows need, with networks (True) or without (False)."""
    out = {}
    n = len(sets.test)
    for name, variant in variants.items():
        v = Variant(*variant)
        cross_fit = folds[any(t == "dynamics" for t in (*v.terms, *v.recognised_by))] if v.cross_fitted else None
        scoring = SkillScoring(tuple(v.terms), v.course, tuple(v.recognised_by), v.forgetting, v.rule, tuple(v.tails),
                               tuple(v.correlated), v.scaled)
        cal = memory.calibrate(sets.precision.data, sets.precision.skills, sets.threshold.data, sets.threshold.skills,
                               sets.threshold.lengths, scoring, config.fprs, cross_fit=cross_fit)
        inferred, posterior = memory.score(sets.test.data)
        told, _ = memory.score(sets.test.data, told=sets.test.skills)
        index = np.array([memory.index(s) for s in sets.test.skills])
        out[f"{name}, not told"] = {**metrics(Scored(inferred, {f: np.full(n, cal.inferred[f]) for f in config.fprs}),
                                              sets, w, config), **named(memory, posterior, sets, w)}
        out[f"{name}, told"] = metrics(Scored(told, {f: cal.told[f][index] for f in config.fprs}), sets, w, config)
    return out


def named(memory: SkillMemory, posterior: np.ndarray, sets: Sets, w: Windows) -> dict[str, float]:
    """How often the most probable skill names a normal test segment's skill at its last step, and
    skill 5 at a no_object window's end (delta 0.5 s)."""
    skills = np.array(memory.skills)
    last = skills[posterior[w.normal, :, sets.test.lengths[w.normal] - 1].argmax(axis=1)]
    ends = dict(zip(w.items, w.ends[0.5]))
    rows = [i for i in w.anomalous if sets.test.anomalies[i] == "no_object"]
    at_end = skills[[int(posterior[i, :, ends[i]].argmax()) for i in rows]]
    return {"recognised": float(np.mean(last == sets.test.skills[w.normal])), "no_object_as_5": float(np.mean(at_end == "5"))}


def template_told(sets: Sets, config: KittingConfig) -> Scored:
    """The benchmark's told template (`score_baselines`' template_told)."""
    normaliser = Normaliser.fit(sets.train.data)
    template = PerSkillZScore().fit(normaliser.normalise(sets.train.data), sets.train.skills, [], 0)
    return calibrated_energies(lambda s: normaliser.normalise(s.data) - template.expected(normaliser.normalise(s.data),
                                                                                         s.skills), sets, config.fprs)


def one_split(config: KittingConfig, cache: Path, only: str = "", benchmark: bool = True) -> dict[str, list[dict[str, float]]]:
    """Every row on one split, three trainings; ``benchmark``: with the benchmark's network's rows."""
    config, _, _, sets, w = setup(config)
    rows: dict[str, list[dict[str, float]]] = {}
    for seed in config.seeds:
        start = time.perf_counter()
        memory = skill_memory(sets, config, seed, cache)
        def one() -> NeuralASM:
            return cached(cache / f"seed{seed}_one.safetensors", lambda: fit_network(sets.train, config, seed))

        variants = {k: v for k, v in VARIANTS.items() if only in k}
        needs = {any(t == "dynamics" for t in (*Variant(*v).terms, *Variant(*v).recognised_by))
                 for v in variants.values() if Variant(*v).cross_fitted} | {False}
        folds = {network: out_of_fold(memory, sets, config, seed, cache, network) for network in needs}
        for name, row in memory_rows(memory, sets, w, config, variants, folds).items():
            rows.setdefault(name, []).append(row)
        if seed == config.seeds[0]:
            rivals = {"template_likelihood": TEMPLATE_LIKELIHOOD,
                      "template_likelihood, cross-fitted": TEMPLATE_LIKELIHOOD._replace(cross_fitted=True)}
            for name, row in memory_rows(memory, sets, w, config, rivals, folds).items():
                rival = name.replace("template_likelihood", "template_likelihood (rival)")
                if name.endswith("not told"):
                    rows[rival] = [row]
                elif "cross-fitted" in name:  # told, the mean course is the told template
                    rows["template (the mean course) (rival), cross-fitted, told"] = [row]
            rows["template_told (rival), told"] = [metrics(template_told(sets, config), sets, w, config)]
        for mode, name in (("online", "nasm_one_online"), ("offline", "nasm_one")) if benchmark else ():
            rows.setdefault(f"{name} (benchmark), not told", []).append(
                metrics(score_network(one(), sets, mode, True, config.fprs), sets, w, config))
        print(f"split {config.split_seed} seed {seed}: {time.perf_counter() - start:.0f} s", flush=True)
    return rows


def paired(rows: dict[str, list[dict]], memory: str, rival: str) -> str:
    """Exact McNemar on the served decisions of ``memory`` (each training) against ``rival`` (its one
    "training"): the discordant items summed over trainings, and each training's p."""
    a_runs, (b,) = [r["correct"] for r in rows[memory]], [r["correct"] for r in rows[rival]]
    a_only = [int((a & ~b).sum()) for a in a_runs]
    b_only = [int((~a & b).sum()) for a in a_runs]
    each = ", ".join(f"{x}/{y} p={mcnemar_exact(x, y):.2g}" for x, y in zip(a_only, b_only))
    return (f"| {memory} | {rival} | {sum(a_only)} | {sum(b_only)} | {mcnemar_exact(sum(a_only), sum(b_only)):.2g} | "
            f"{each} |")


def paired_table(by_split: dict[int, dict[str, list[dict]]]) -> str:
    """Every round-2 row against the strongest rivals (held-out and cross-fitted thresholds)."""
    lines = ["| split | memory | rival | memory only right (sum of trainings) | rival only right | p (summed) | "
             "per training: memory only / rival only, p |", "|---|---|---|---|---|---|---|"]
    for split, rows in by_split.items():
        for name in (r for r in rows if r.startswith(("r2: ", "r4: ", "r5: "))):
            rivals = (("template_likelihood (rival), not told", "template_likelihood (rival), cross-fitted, not told")
                      if name.endswith("not told") else
                      ("template_told (rival), told", "template (the mean course) (rival), cross-fitted, told"))
            lines += [f"| {split} " + paired(rows, name, rival) for rival in rivals if rival in rows]
    return "\n".join(lines)


def cell(runs: list[dict[str, float]], key: str) -> str:
    if key not in runs[0]:
        return "–"
    values = np.array([r[key] for r in runs], float)
    pct = key in ("detected", "normal_flagged", "recognised", "no_object_as_5")
    fmt = (lambda v: f"{100 * v:.0f} %") if pct else (lambda v: f"{v:.0f}") if key == "delay_ms" else (lambda v: f"{v:.3f}")
    if len(values) == 1 or np.ptp(values) == 0:
        return fmt(values.mean())
    return f"{fmt(values.mean())} ({fmt(values.min())}-{fmt(values.max())})"


def table(by_split: dict[int, dict[str, list[dict[str, float]]]]) -> str:
    lines = ["| split | method | mean AUROC 3-5 | skill 5 | no_object | detected 1 % | normal flagged 1 % | delay median (ms) "
             "| normal recognised | no_object named 5 |", "|---|---|---|---|---|---|---|---|---|---|"]
    for split, rows in by_split.items():
        lines += [f"| {split} | {name} | " + " | ".join(cell(runs, k) for k in COLUMNS_OUT) + " |"
                  for name, runs in rows.items()]
    types = sorted(next(iter(next(iter(by_split.values())).values()))[0]["per_type"])
    lines += ["", "| split | method | " + " | ".join(types) + " |", "|---|---|" + "---|" * len(types)]
    for split, rows in by_split.items():
        lines += [f"| {split} | {name} | " + " | ".join(
            f"{np.mean([r['per_type'][t] for r in runs]):.2f}" for t in types) + " |" for name, runs in rows.items()]
    return "\n".join(lines)


def main(data: Path = typer.Argument(..., help="the clone's 'No.0 filtering scheme' folder"),
         splits: list[int] = typer.Option([0, 1, 2]), seeds: int = typer.Option(3, min=1),
         cache: Path = typer.Option(Path("kitting_skills_cache"), help="trained networks, per split and seed"),
         out: Path | None = typer.Option(None, help="also write the table here"),
         only: str = typer.Option("", help="only the memory's variants whose name holds this text"),
         benchmark: bool = typer.Option(True, help="also the benchmark's network's rows (nasm_one, nasm_one_online)")) -> None:
    by_split = {}
    for split in splits:
        config = KittingConfig(data=data, out=cache, trainings=seeds, split_seed=split)
        by_split[split] = one_split(config, cache / f"split{split}", only, benchmark)
        print(table({split: by_split[split]}), flush=True)
    text = table(by_split) + "\n\n" + paired_table(by_split)
    print(text)
    if out is not None:
        out.write_text(text + "\n")


if __name__ == "__main__":
    typer.run(main)
