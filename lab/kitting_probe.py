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

``--probe motion`` (written before it was run): **the skill from the motion, the gripper only
scored.** Hypothesis: if the hidden state is relaxed with zero precision on the tactile channels
(their errors do not move z; W_F still learns to expect them by its local rule at their full
precision; the calibration still scores them), and the served calibration recognises the skill
from the errors of the force, torque and speed channels only, then a ``no_object`` segment is
recognised as skill 5 by its motion and its empty gripper becomes a prediction error: its AUROC at
0.5 s rises from 0.48 (offline) / 0.55 (online) toward the oracle's 0.85. Measured on the
benchmark's split, windows and calibration, three trainings of each network (seeds 0-2, the
product's network trained afresh beside the split ones): mean AUROC over skills 3-5, skill 5 and
``no_object`` at 0.5 s, detected and normal flagged at the served 1 % threshold, offline (served)
and online, recognition from every channel (served) or the motion channels; and how often the
recognised skill is right (normal test segments, at their last step) and names skill 5 for a
``no_object`` window (at its end). Adopted if the mean AUROC and ``no_object`` rise beyond the
trainings' range with <= 2 % of normal segments flagged. Beside it, from the data alone: which
skill a z-score template of the motion channels names for the ``no_object`` windows (and, added
after the run, when the arm starts moving in each day's normal skill-5 and ``no_object`` segments).

    python -m lab.kitting_probe "$SCHEME" --probe motion [--seeds 3]
"""

from __future__ import annotations

from collections import Counter
from dataclasses import replace
from pathlib import Path
from unittest.mock import patch

import numpy as np
import typer

from neural_asm.experiments.kitting.config import KittingConfig
from neural_asm.experiments.kitting.data import Segments, Split, read_segments, run_of, split_runs, whole_runs_mapping
from neural_asm.experiments.kitting.methods import Scored, Sets, calibrate_served, fit_network, served_thresholds
from neural_asm.experiments.kitting.metrics import Windows, method_metrics, windows
from neural_asm.experiments.kitting.run import make_sets
from neural_asm.experiments.kitting.whole_runs import PhaseAnswer, RunLabels, count_whole_runs, run_labels
from neural_asm.logs.sources import read_mapped
from neural_asm.logs.tables import phase_keys
from neural_asm.models import asm
from neural_asm.models.asm import NeuralASM
from neural_asm.models.calibration import Calibration, conformal_episode_threshold
from neural_asm.models.fault import is_fault
from neural_asm.models.kernels import gauss_newton
from neural_asm.models.normaliser import Normaliser
from neural_asm.models.scoring import quadratic, step_rows
from neural_asm.models.sequences import Sequences
from neural_asm.models.tpc import TemporalPC

TACTILE = [4, 5]
MIN_SKILL_EPISODES = 5
HELD = (1, 20)  # steps the skill is recognised from before it is held
MOTION = [0, 1, 2, 3]  # force and torque norms, end-effector linear and angular speeds
SPLITS = {"every channel drives z (the product)": (), "tactile scored only": (4, 5),
          "speeds drive z; force, torque, tactile scored only": (0, 1, 4, 5)}


class ScoredOnly(TemporalPC):
    """The tPC relaxed with zero precision on the ``scored`` channels: their errors do not move z,
    while W_F's local rule (`hebbian_terms`, at their full precision) still learns to expect them."""

    scored: tuple[int, ...] = ()

    def _gauss_newton(self, prior: np.ndarray, x: np.ndarray, steps: int) -> np.ndarray:
        scale = self.pi_sqrt.copy()
        scale[list(self.scored)] = 0.0
        return gauss_newton(np.ascontiguousarray(prior, np.float32), np.ascontiguousarray(x, np.float32), self.w_f,
                            scale, steps)


def fit_split(train: Segments, config: KittingConfig, seed: int, scored: tuple[int, ...]) -> NeuralASM:
    """The benchmark's network with ``scored`` channels kept out of the relaxation (none: the product's)."""
    assert config.network.solver == "gauss_newton"
    net = type("ScoredOnlyNet", (ScoredOnly,), {"scored": scored})
    with patch.object(asm, "TemporalPC", net):
        return fit_network(train, config, seed)


def recognised_from(cal: Calibration, errors: np.ndarray, channels: list[int]) -> np.ndarray:
    """`Calibration.recognised` with each skill's misfit summed over ``channels`` only."""
    steps = errors.shape[1]
    means = cal._means_at(np.arange(steps))[:-1][..., channels]
    spread = step_rows(cal.error_std, steps)[:, channels]
    misfit = (((errors[:, None][..., channels] - means[None]) / spread) ** 2).sum(-1)
    before = np.cumsum(misfit, axis=2)[..., :-1]
    return np.concatenate([np.full((len(errors), 1), -1), before.argmin(axis=1)], axis=1)


def picks(cal: Calibration, errors: np.ndarray, segs, recognition: str, k: int) -> np.ndarray:
    """(N, T) the skill (index; -1 the skills' average) whose mean errors centre each step."""
    steps = errors.shape[1]
    if recognition == "told":
        told = [cal.skills.index(s) if s in cal.skills else -1 for s in segs.skills]
        return np.repeat(np.array(told)[:, None], steps, axis=1)
    if recognition == "motion":
        return recognised_from(cal, errors, MOTION)
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
    names = np.array([*cal.skills, "none"])
    last = pick_te[w.normal, sets.test.lengths[w.normal] - 1]
    no_object = w.anomalous[sets.test.anomalies[w.anomalous] == "no_object"]
    at_end = pick_te[no_object, w.ends[0.5][: len(w.anomalous)][np.isin(w.anomalous, no_object)]]
    return {"auroc": m["auroc"]["0.5"], "skill_5": m["per_skill"]["5"]["auroc"]["0.5"],
            "no_object": m["per_type"]["no_object"]["auroc_0.5"], "detected": m["detected_1pct"],
            "normal_flagged": m["normal_flagged_1pct"],
            "recognised_normal": float(np.mean(names[last] == sets.test.skills[w.normal])),
            "no_object_as_5": float(np.mean(names[at_end] == "5"))}


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


def motion_template(sets: Sets, w: Windows) -> dict[str, int]:
    """The skill a z-score template of the motion channels (pooled spreads) names for each
    ``no_object`` window at its end (delta 0.5 s), from the data alone."""
    norm = Normaliser.fit(sets.train.data)
    skills = sorted(set(sets.train.skills))
    x = norm.normalise(sets.train.data)[..., MOTION]
    means = np.stack([x[sets.train.skills == s].mean(0) for s in skills])
    spread = np.sqrt(np.mean([((x[sets.train.skills == s] - means[i]) ** 2).mean(0) for i, s in enumerate(skills)], 0))
    rows = w.anomalous[sets.test.anomalies[w.anomalous] == "no_object"]
    ends = w.ends[0.5][: len(w.anomalous)][np.isin(w.anomalous, rows)]
    misfit = (((norm.normalise(sets.test.data[rows])[..., MOTION][:, None] - means[None]) / spread) ** 2).sum(-1)
    fit = np.cumsum(misfit, axis=2)[np.arange(len(rows)), :, ends]
    return dict(Counter(skills[i] for i in fit.argmin(1)))


def print_table(rows: dict[str, list[dict[str, float]]]) -> None:
    keys = list(next(iter(rows.values()))[0])
    print("| variant | " + " | ".join(keys) + " |\n|---|" + "---|" * len(keys))
    for name, runs in rows.items():
        cells = [f"{np.mean([r[k] for r in runs]):.2f} ({min(r[k] for r in runs):.2f}-{max(r[k] for r in runs):.2f})"
                 for k in runs[0]]
        print(f"| {name} | " + " | ".join(cells) + " |")


def whole_run_phases(config: KittingConfig, split: Split, folder: Path) -> tuple[Sequences, dict[str, RunLabels]]:
    """The test runs' tagged phases as the benchmark replays them, and each run's labels."""
    runs = [f for f in (config.data / "whole_experiment" / f"experiment_at_{r}" for r in split.test) if f.is_dir()]
    folder.mkdir(parents=True, exist_ok=True)
    for run in runs:
        if not (folder / run.name).exists():
            (folder / run.name).symlink_to(run.resolve(), target_is_directory=True)
    return read_mapped(folder, whole_runs_mapping()), {run_of(f.name): run_labels(f) for f in runs}


def whole_runs(model: NeuralASM, phases: Sequences, labels: dict[str, RunLabels],
               config: KittingConfig, table: np.ndarray | None = None,
               recognised: np.ndarray | None = None, scales: np.ndarray | None = None) -> dict[str, float]:
    """The benchmark's whole-run counts (`count_whole_runs`) from the model's served calibration in
    ``config.recall_mode`` (offline in every probe but one) scoring each phase in process (what the
    served sessions answer: the benchmark's tests hold them equal), each phase over its own steps.
    With ``table``, each step held to the threshold of the skill recognised at it (the last entry:
    no skill recognised yet); with ``recognised`` (N, T), the skills (indices, -1 none) that centre
    each step instead of the served ones; with ``scales`` (T',), each step's energy divided by its
    scale (the last one past T': a time-varying threshold, the calibration's episode threshold then
    its q)."""
    cal = model.calibration(config.recall_mode, 1)
    errors = model.errors(phases.data, config.recall_mode)
    if recognised is None:
        energies_, picks_ = cal.energy(errors), cal.recognised(errors.astype(np.float64))
    else:
        energies_, picks_ = energies(cal, errors.astype(np.float64), recognised), recognised
    if table is not None:
        energies_, cal = energies_ / table[picks_], replace(cal, episode_thresholds={0.01: 1.0})
    if scales is not None:
        energies_ = energies_ / scales[np.minimum(np.arange(energies_.shape[1]), len(scales) - 1)]
    answered = [PhaseAnswer(run_of(phases.episodes[i].origin), str(phases.labels[i]), phases.episodes[i].start_s,
                            is_fault(energies_[i, :n], cal.episode_thresholds[0.01]),
                            tuple(None if k < 0 else cal.skills[k] for k in picks_[i, :n]))
                for i in range(len(phases.data)) for n in (phases.own_steps(i),)]
    counts = count_whole_runs(answered, labels, cal.skills, config.not_anomalies)
    clean = [a for a in answered if not _holds_onset(a, labels[a.run], config)]
    counts["clean_recognised"] = count_whole_runs(clean, labels, cal.skills, config.not_anomalies)["skill_recognised"]
    return {f"whole_{k}": counts[k] for k in ("flagged_within_1s", "flagged_early", "clean_phases_flagged",
                                              "skill_recognised", "clean_recognised")}


def _holds_onset(answer: PhaseAnswer, labels: RunLabels, config: KittingConfig) -> bool:
    """Whether a replayed phase holds a labelled anomaly's onset (`count_whole_runs`' clean phases do not)."""
    onsets = np.array([a.time_s for a in labels.anomalies if a.label not in config.not_anomalies])
    k = phase_keys(np.array([answer.start_s]), list(labels.phases))[0]
    return bool(len(onsets)) and bool((phase_keys(onsets, list(labels.phases)) == k).any())


def peak_channels(model: NeuralASM, sets: Sets, w: Windows) -> dict[str, np.ndarray]:
    """Each channel's mean share of the energy's peak (its squared weighted error there) in the
    ``no_object`` and normal windows at 0.5 s, under the served offline calibration."""
    cal = model.calibration("offline", 1)
    errors = model.errors(sets.test.data, "offline")
    energy, weighed = cal.energy(errors), cal.weigh(errors)
    ends = dict(zip(w.items, w.ends[0.5]))
    out = {}
    for name, rows in (("no_object", w.anomalous[sets.test.anomalies[w.anomalous] == "no_object"]),
                       ("normal", w.normal)):
        at = [int(np.argmax(energy[i, : ends[i] + 1])) for i in rows]
        out[name] = np.round(np.mean([weighed[i, t] ** 2 for i, t in zip(rows, at)], axis=0), 2)
    return out


def motion_by_day(segs: Segments) -> dict[str, dict[str, object]]:
    """Per day of runs: how many normal skill-5 and ``no_object`` segments it holds, and the median
    step at which their end effector's linear speed first exceeds 0.05 m/s (whether the motion that
    sets ``no_object`` apart is the failure or its day's)."""
    day = np.array([r[:10] for r in segs.runs])
    rise = np.array([int(np.argmax(x[:, 2] > 0.05)) if (x[:, 2] > 0.05).any() else -1 for x in segs.data])
    out = {}
    for d in sorted(set(day)):
        for name, rows in (("normal 5", segs.normal & (segs.skills == "5") & (day == d)),
                           ("no_object", (segs.anomalies == "no_object") & (day == d))):
            if rows.any():
                out.setdefault(d, {})[name] = (int(rows.sum()), float(np.median(rise[rows])))
    return out


def motion(sets: Sets, w: Windows, config: KittingConfig, split: Split, segs: Segments) -> None:
    """The ``--probe motion`` measurement (the module's docstring)."""
    print("no_object windows named by a motion template:", motion_template(sets, w))
    print("(segments, median step the linear speed first exceeds 0.05 m/s) by day:", motion_by_day(segs))
    phases, labels = whole_run_phases(config, split, Path(config.out) / "kitting_probe_runs")
    rows: dict[str, list[dict[str, float]]] = {}
    for seed in config.seeds:
        for name, scored in SPLITS.items():
            model = fit_split(sets.train, config, seed, scored)
            for mode in ("online", "offline"):  # offline last: the served calibration whole runs are scored by
                for recognition in ("every step", "motion"):
                    by = "every channel" if recognition == "every step" else "the motion channels"
                    rows.setdefault(f"{name}, {mode}, skill recognised from {by}", []).append(
                        variant(model, sets, w, config, mode, recognition, 0, False))
            rows[f"{name}, offline, skill recognised from every channel"][-1].update(whole_runs(model, phases, labels,
                                                                                                config))
            if seed == config.seeds[0]:
                print(f"{name}, seed {seed}: squared weighted errors at the peak, per channel:",
                      peak_channels(model, sets, w))
    print_table({k: v for k, v in rows.items() if "whole_skill_recognised" not in v[0]})
    print_table({k: v for k, v in rows.items() if "whole_skill_recognised" in v[0]})


def setup(config: KittingConfig) -> tuple[KittingConfig, Segments, Split, Sets, Windows]:
    """The benchmark's segments, split, sets and onset windows for ``config`` (every probe's start)."""
    segs = read_segments(config.data)
    split = split_runs(segs.runs, config.train_fraction, config.split_seed)
    sets = make_sets(segs, split)
    return config, segs, split, sets, windows(sets.test, config, config.headline_skills)


def main(data: Path = typer.Argument(..., help="the clone's 'No.0 filtering scheme' folder"),
         seeds: int = typer.Option(3, min=1), probe: str = typer.Option("rule", help="rule | motion"),
         out: Path = typer.Option(Path("."), help="where --probe motion links the test runs")) -> None:
    config, segs, split, sets, w = setup(KittingConfig(data=data, out=out, trainings=seeds))
    if probe == "motion":
        return motion(sets, w, config, split, segs)
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
    print_table(rows)
    for name, m in templates(sets, w, config).items():
        print(f"template of every skill, not told, {name}: " + ", ".join(f"{k} {v:.2f}" for k, v in m.items()))


if __name__ == "__main__":
    typer.run(main)
