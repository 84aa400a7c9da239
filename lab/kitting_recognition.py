"""Does the one network's hidden state know which skill it runs, where the served recognition does
not? A probe beside the kitting benchmark (docs/kitting.md, "Which skill: the hidden state or the
mean errors").

Written before it was run. The service recognises the skill as the one whose mean prediction
errors (per step, from the calibration's held-out runs) best explain the errors so far
(`Calibration.recognised`); on the whole runs of the test split it names the tagged skill at a
phase's last step in 58 % of phases (49-76 % over three trainings; 64 % of the normal test
segments). The paper places the skill in the inferred hidden state z ("contextual inference").
**Hypothesis**: in online recall (z inferred at every step), a linear read-out of z — a
multinomial logistic regression on the running mean of z over the steps so far, fitted on the
training runs' normal segments only, each step a sample — names the skill at a phase's end in
>= 90 % of the whole-run phases, and at the end of >= 90 % of normal test segments.
**Decision**: if so, a read-out of z is worth building into the served recognition (which centres
the errors and names the `skill` of each answer); if not, the six channels do not tell the skills
apart at their ends either, and the whole-run recognition target is out of reach of any
recognition from these channels. For reference, beside it: the same read-out of the running mean
of the observations themselves (no network), which shows what the channels hold.

Three trainings (seeds 0-2), the benchmark's split; "no_object named 5": the share of the 14
``no_object`` segments of which the recogniser names skill 5 at onset + 0.5 s. Per skill, the
share of its whole-run phases named right (added after the first run).

**Second question** (written after the first run, before this one): does the served rule gain
from the better recognition? The same offline errors (the service's default), each step centred
by the mean errors of the skill z's read-out names from the steps before it (as the served
recognition uses the steps before), the episode threshold set likewise on the threshold half.
**Hypothesis**: the mean AUROC over skills 3-5 at 0.5 s rises from 0.83 toward the told oracle's
0.91, `no_object` does not (never named 5), detection at 1 % stays near the oracle's 27 % (the
threshold is skill 5's normal tail). **Decision**: worth building into the service if the AUROC
rises beyond the trainings' range with <= 2 % of normal test segments flagged and the whole runs'
early flags and clean phases flagged within their targets (<= 5 %).

    python -m lab.kitting_recognition "$SCHEME" [--seeds 3] [--out DIR]
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import typer
from sklearn.linear_model import LogisticRegression
from sklearn.pipeline import make_pipeline
from sklearn.preprocessing import StandardScaler

from lab.kitting_probe import energies, print_table, setup, whole_run_phases, whole_runs
from lab.kitting_thresholds import measured
from neural_asm.experiments.kitting.config import KittingConfig
from neural_asm.experiments.kitting.data import PERIOD_S
from neural_asm.experiments.kitting.methods import Scored, Sets, calibrate_served, fit_network, served_thresholds
from neural_asm.experiments.kitting.metrics import Windows
from neural_asm.models.asm import NeuralASM
from neural_asm.models.calibration import Calibration
from neural_asm.models.recall import Recaller

HEADLINE = 0.5  # s after the onset


def online_states(model: NeuralASM, data: np.ndarray) -> np.ndarray:
    """(N, T, H) the hidden state inferred at every step in online recall."""
    x = model.normaliser.normalise(data.astype(np.float32))
    recaller = Recaller(model.net, len(x), "online", 1, None)
    states = []
    for t in range(x.shape[1]):
        recaller.step(x[:, t])
        states.append(recaller.zhat.copy())
    return np.stack(states, axis=1)


def running_mean(values: np.ndarray) -> np.ndarray:
    """(N, T, F) the mean of each feature over the steps so far."""
    return np.cumsum(values, axis=1) / np.arange(1, values.shape[1] + 1)[None, :, None]


def fit_readout(features: np.ndarray, lengths: np.ndarray, skills: np.ndarray):
    """A multinomial logistic regression of the skill on every own step's features."""
    rows = np.concatenate([f[:n] for f, n in zip(features, lengths)])
    labels = np.concatenate([[s] * n for s, n in zip(skills, lengths)])
    return make_pipeline(StandardScaler(), LogisticRegression(max_iter=3000)).fit(rows, labels)


def named_at(readout, features: np.ndarray, steps: np.ndarray) -> np.ndarray:
    """The skill the read-out names at one step of each sequence."""
    return readout.predict(features[np.arange(len(features)), steps])


def picks_from(readout, features: np.ndarray, skills: tuple[str, ...]) -> np.ndarray:
    """(N, T) the skill (index into ``skills``; -1 none) the read-out names from the steps before
    each step, as `Calibration.recognised` names it from the errors before it."""
    n, steps, width = features.shape
    named = readout.predict(features.reshape(-1, width)).reshape(n, steps)
    index = np.array([[skills.index(s) if s in skills else -1 for s in row] for row in named])
    return np.concatenate([np.full((n, 1), -1), index[:, :-1]], axis=1)


def served_rule(model: NeuralASM, cal: Calibration, sets: Sets, w: Windows, config: KittingConfig,
                recognised: dict[str, np.ndarray] | None) -> dict[str, float]:
    """The served offline rule's numbers, with the served recognition (None) or the given one
    (for the "threshold" and "test" sets) centring each step; the model's 1 % threshold set to match."""
    thresholds, scored = {}, {}
    for name in ("threshold", "test"):
        segs = getattr(sets, name)
        if recognised is None:
            scored[name] = model.score(segs.data, config.recall_mode).energy
        else:
            errors = model.errors(segs.data, config.recall_mode).astype(np.float64)
            scored[name] = energies(cal, errors, recognised[name])
    thresholds = served_thresholds(scored["threshold"], sets.threshold.lengths, config.fprs)
    cal.episode_thresholds.update(thresholds)
    return measured(Scored(scored["test"], {f: np.full(len(sets.test), t) for f, t in thresholds.items()}), sets, w,
                    config)


def main(data: Path = typer.Argument(..., help="the clone's 'No.0 filtering scheme' folder"),
         seeds: int = typer.Option(3, min=1),
         out: Path = typer.Option(Path("."), help="where the test runs are linked for the whole-run phases")) -> None:
    config, _, split, sets, w = setup(KittingConfig(data=data, out=out, trainings=seeds))
    phases, labels = whole_run_phases(config, split, out / "kitting_probe_runs")
    phase_steps = np.array([phases.own_steps(i) for i in range(len(phases.data))])
    known = np.isin(phases.labels.astype(str), np.unique(sets.train.skills))
    phase_skills, phase_ends = phases.labels.astype(str)[known], phase_steps[known] - 1
    test = sets.test
    normal, normal_ends = np.flatnonzero(test.normal), test.lengths[test.normal] - 1
    no_object = w.anomalous[test.anomalies[w.anomalous] == "no_object"]
    no_object_ends = np.minimum(test.onsets[no_object] + int(round(HEADLINE / PERIOD_S)), test.lengths[no_object] - 1)

    def scores(named_phase: np.ndarray, named_normal: np.ndarray, named_no_object: np.ndarray) -> dict[str, float]:
        right = named_phase == phase_skills
        return {"whole-run phases": float(np.mean(right)),
                **{f"phases of skill {k}": float(np.mean(right[phase_skills == k])) for k in sorted(set(phase_skills))},
                "normal test segments": float(np.mean(named_normal == test.skills[normal])),
                "no_object named 5": float(np.mean(named_no_object == "5"))}

    rows: dict[str, list[dict[str, float]]] = {}
    rule: dict[str, list[dict[str, float]]] = {}
    observed = {k: running_mean(model_free) for k, model_free in
                (("train", sets.train.data), ("test", test.data), ("phases", phases.data[known]))}
    readout = fit_readout(observed["train"], sets.train.lengths, sets.train.skills)
    rows["read-out of the observations' running mean (no network)"] = [scores(
        named_at(readout, observed["phases"], phase_ends), named_at(readout, observed["test"][normal], normal_ends),
        named_at(readout, observed["test"][no_object], no_object_ends))]
    for seed in config.seeds:
        model = fit_network(sets.train, config, seed)
        cal = calibrate_served(model, sets, config.recall_mode, True, config.fprs)
        names = np.array([*cal.skills, "none"])

        def served(x: np.ndarray, ends: np.ndarray) -> np.ndarray:
            picks = cal.recognised(model.errors(x, config.recall_mode).astype(np.float64))
            return names[picks[np.arange(len(x)), ends]]

        rows.setdefault("served: mean errors, offline recall", []).append(scores(
            served(phases.data[known], phase_ends), served(test.data[normal], normal_ends),
            served(test.data[no_object], no_object_ends)))
        z = {k: running_mean(online_states(model, x)) for k, x in
             (("train", sets.train.data), ("threshold", sets.threshold.data), ("test", test.data),
              ("phases", phases.data))}
        readout = fit_readout(z["train"], sets.train.lengths, sets.train.skills)
        rows.setdefault("read-out of z's running mean, online recall", []).append(scores(
            named_at(readout, z["phases"][known], phase_ends), named_at(readout, z["test"][normal], normal_ends),
            named_at(readout, z["test"][no_object], no_object_ends)))
        rule.setdefault("served: mean errors recognise the skill", []).append(
            {**served_rule(model, cal, sets, w, config, None), **whole_runs(model, phases, labels, config)})
        by_z = {k: picks_from(readout, z[k], cal.skills) for k in ("threshold", "test", "phases")}
        rule.setdefault("z's read-out recognises the skill", []).append(
            {**served_rule(model, cal, sets, w, config, by_z),
             **whole_runs(model, phases, labels, config, recognised=by_z["phases"])})
    print(f"{int(known.sum())} whole-run phases of known skills, {len(normal)} normal test segments, "
          f"{len(no_object)} no_object segments")
    print_table(rows)
    print_table(rule)


if __name__ == "__main__":
    typer.run(main)
