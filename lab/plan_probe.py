"""What does the best rival have that the network lacks? A plan its expectation returns to.

A probe beyond the benchmark (docs/varied_levers.md). The conditional template with a one-step
residual predictor catches more visible faults than the featured network, locks above all, although
it expects held-out normal episodes worse. The hypothesis: an expectation made of a plan fixed
from the cue plus a model of the episode's departure from it keeps expecting the plan's motion
after a lock, where a one-step predictor of the observations, which reads the arm's own last
motion, expects the locked arm to stay. Each row is scored by the benchmark's own code:

- the linear one-step predictor pooled over skills (not told the skill, as the network is not),
  and the same with a plan term B_t c: per step, a linear map of the whole first observation (a
  cue-conditioned plan in the prediction, the tPC's input term made phase-dependent);
- the template with its residual predictor weighted by kappa = 0, 0.5 and 1 (1 is the rival,
  0 the template alone), and the rival fitted as one model for every skill;
- the network's own offline plan, recalled from the cue, as the template, plus a linear one-step
  predictor of the residual, pooled or per skill; and the network's plan recall, the served mode
  that grew out of this probe (models/plan.py), and the same with the network's part taken out
  (the input and departure pathways alone, a linear model); one row per training.

    python -m lab.plan_probe DATA_DIR [--context hidden] [--seeds 3]
"""

from __future__ import annotations

import copy
from pathlib import Path

import numpy as np
import typer
from sklearn.linear_model import LogisticRegression
from sklearn.pipeline import make_pipeline
from sklearn.preprocessing import StandardScaler
from tqdm.auto import tqdm

from neural_asm.experiments.methods import Method, neural_asm_methods
from neural_asm.experiments.varied.data import VariedBenchmark, load_varied_benchmark
from neural_asm.experiments.varied.methods import train_neural_asm
from neural_asm.experiments.varied.outcomes import ALPHA, outcomes, summary
from neural_asm.experiments.varied.pairs import validation_scores
from neural_asm.experiments.varied.score import energies
from neural_asm.models.asm import NeuralASM
from neural_asm.models.config import PRECISE
from neural_asm.models.one_step import episode_folds
from neural_asm.rivals.base import DetectorBase
from neural_asm.models.normaliser import Normaliser
from neural_asm.models.one_step import ONE_STEP_RIDGES, delay_embed, fit_one_step
from neural_asm.rivals.one_step import TemplateResidualOneStep
from neural_asm.models.plan import PlanMemory
from neural_asm.models.recall import offline_recall

LAGS = 2  # the pooled linear model's choice on the demonstrations (models.one_step.fit_one_step)


def plan_features(x: np.ndarray, steps: int, lags: int, plan: bool) -> np.ndarray:
    """(N, T-1, F) inputs predicting steps 1..T-1 of x (N, T, D): the last `lags` steps and,
    with `plan`, the first observation (and a one) placed in the block of the predicted step, so
    that each step has its own linear map of the cue. `steps` is the demonstrations' length."""
    n, t, d = x.shape
    parts = [delay_embed(x, lags)[:, :-1]]
    if plan:
        cue = np.concatenate([x[:, 0], np.ones((n, 1))], axis=1)
        step = np.eye(steps)[1:t]  # the one-hot of the predicted step
        parts.append((step[None, :, :, None] * cue[:, None, None, :]).reshape(n, t - 1, steps * (d + 1)))
    return np.concatenate(parts, axis=2)


class PlanOneStep(DetectorBase):
    """x[t] ridge-regressed on the last `lags` steps (and, with `plan`, on B_t times the cue), one
    model for every skill; the ridge chosen by 5-fold cross-validation over whole demonstrations."""

    name = "plan_one_step"
    label = "linear one-step predictor pooled over skills, with a per-step map of the cue"

    def __init__(self, plan: bool = True, lags: int = LAGS) -> None:
        super().__init__()
        self.plan, self.lags = plan, lags

    def _solve(self, x: np.ndarray, ridge: float) -> np.ndarray:
        f = plan_features(x, self.steps, self.lags, self.plan).reshape(-1, self._width)
        a = np.hstack([f, np.ones((len(f), 1))])
        y = x[:, 1:].reshape(-1, x.shape[2])
        reg = ridge * np.eye(a.shape[1])
        reg[-1, -1] = 0.0
        return np.linalg.solve(a.T @ a + reg, a.T @ y)

    def _predict(self, weights: np.ndarray, x: np.ndarray) -> np.ndarray:
        f = plan_features(x, self.steps, self.lags, self.plan)
        return np.concatenate([f, np.ones(f.shape[:2] + (1,))], axis=2) @ weights

    def _fit(self, x: np.ndarray, skills: np.ndarray, seed: int) -> None:
        self._width = plan_features(x[:1], self.steps, self.lags, self.plan).shape[2]
        folds = episode_folds(skills, seed)

        def cv_error(ridge: float) -> float:
            return sum(float(((self._predict(self._solve(x[train], ridge), x[test]) - x[test, 1:]) ** 2).sum())
                       for train, test in folds)

        self.ridge = min(ONE_STEP_RIDGES, key=cv_error)
        self.weights = self._solve(x, self.ridge)

    def _expected(self, x: np.ndarray, skills: np.ndarray) -> np.ndarray:
        out = x.astype(np.float64)
        if x.shape[1] > 1:
            out[:, 1:] = self._predict(self.weights, x)
        return out


def network_plan_residual(model: NeuralASM, demos: np.ndarray, skills: np.ndarray, per_skill: bool
                          ) -> Method:
    """The network's offline plan from the cue plus a linear one-step predictor of the departure
    from it, fitted on the demonstrations (normalised); pooled unless `per_skill` (told the skill)."""
    def plan(x: np.ndarray) -> np.ndarray:
        return offline_recall(model.net, x[:, :1].astype(np.float32), x.shape[1]).astype(np.float64)

    def labels(s: np.ndarray) -> np.ndarray:
        return np.asarray(s) if per_skill else np.full(len(s), "all")

    one_step = fit_one_step(demos - plan(demos), labels(skills), 0)

    def expected(x: np.ndarray, s: np.ndarray) -> np.ndarray:
        p = plan(x)
        correction = np.zeros_like(p)
        correction[:, 1:] = one_step.predict(x - p, labels(s))
        return p + correction

    told = "per skill (told the skill)" if per_skill else "pooled"
    return Method(f"network_plan_residual_{'skill' if per_skill else 'pooled'}",
                  f"network's offline plan + linear residual predictor, {told}", False, expected)


def skill_recognition(bench: VariedBenchmark, norm: Normaliser) -> float:
    """Share of the test episodes whose skill a logistic regression on the first observation names
    right: whether being told the skill tells a baseline more than the cue does."""
    demos = norm.normalise(bench.demos.data)
    recogniser = make_pipeline(StandardScaler(), LogisticRegression(max_iter=2000)).fit(demos[:, 0], bench.demos.labels)
    return float((recogniser.predict(norm.normalise(bench.test.data)[:, 0]) == bench.test.labels).mean())


def plan_without_states(model: NeuralASM, demos: np.ndarray, skills: np.ndarray) -> Method:
    """Plan recall with the network's part taken out (R_s = 0): the input pathway per step of the
    context and the departure pathways alone, a linear model. What the served mode gains over it
    is what the network's recalled states add."""
    bare = copy.copy(model)
    bare.plan = PlanMemory.fit(model.net, demos, skills, model.plan.context, model.config.seed, with_states=False)
    plan = next(m for m in neural_asm_methods(bare, "nasm", "") if m.name == "nasm_plan")
    return Method("plan_without_states", "plan recall without the network's states (input and departure "
                  "pathways alone)", False, plan.expected)


def row(method: Method, bench: VariedBenchmark, norm: Normaliser, name: str | None = None) -> dict:
    """One method scored by the benchmark's own rule, its energies computed once for every set,
    the validation faults included (no pair of rivals is formed: the probe compares, it does not
    choose)."""
    e, held_out = energies(method, bench, norm, validation=True)
    episode = summary(outcomes(e, bench.onset, ALPHA)["episode"], bench)
    return {"method": name or method.name, "label": method.label, "held_out_mse": held_out["all"],
            "validation_faults": validation_scores(e, bench.validation, ALPHA)[0],
            "held_out_mse_joints": held_out["joints"],
            "visible": episode["detection"], "lock": episode["per_family"]["lock"]["detection_visible"],
            "consequential": episode["consequential"]["detection"],
            "normal_flagged": episode["normal_episode_false_alarm"]}


def main(data: Path, context: str = "observed", seeds: int = typer.Option(3, min=1, help="network trainings")) -> None:
    bench = load_varied_benchmark(data, context)
    norm = Normaliser.fit(bench.demos.data)
    demos, skills, ctx = norm.normalise(bench.demos.data), bench.demos.labels, bench.context_channels.tolist()
    methods = [Method("linear_pooled", "linear one-step, pooled over skills", False,
                      PlanOneStep(plan=False).fit(demos, skills, ctx).expected),
               Method("linear_pooled_plan", "linear one-step, pooled, + per-step map of the cue", False,
                      PlanOneStep(plan=True).fit(demos, skills, ctx).expected)]
    for kappa in (0.0, 0.5, 1.0):
        detector = TemplateResidualOneStep(residual_weight=kappa).fit(demos, skills, ctx)
        methods.append(Method(f"template_residual_{kappa:g}", f"template + {kappa:g} x residual predictor",
                              False, detector.expected))
    pooled = TemplateResidualOneStep().fit(demos, np.full(len(demos), "all"), ctx)
    methods.append(Method("template_residual_pooled", "template + residual predictor, one model for every skill",
                          False, lambda x, _skills: pooled.expected(x, np.full(len(x), "all"))))
    print(f"skill recognised from the first observation: {100 * skill_recognition(bench, norm):.1f} % of test episodes")
    rows = [row(m, bench, norm) for m in tqdm(methods, desc="scoring")]
    for seed in tqdm(range(seeds), desc="trainings"):
        model = train_neural_asm(bench, PRECISE.with_(seed=seed), progress=False)
        own = model.normaliser.normalise(bench.demos.data)
        plans = [network_plan_residual(model, own, skills, per_skill) for per_skill in (False, True)]
        plans += [m for m in neural_asm_methods(model, "nasm", "featured network") if m.name == "nasm_plan"]
        plans.append(plan_without_states(model, own, skills))
        rows += [row(m, bench, model.normaliser, f"{m.name} (training {seed})") for m in plans]
    print("| method | held-out MSE | joints | validation faults detected | visible detected | locks | consequential "
          "| normal flagged |")
    print("|---|---|---|---|---|---|---|---|")
    for r in rows:
        print(f"| {r['method']} | {r['held_out_mse']:.3f} | {r['held_out_mse_joints']:.3f} "
              f"| {100 * r['validation_faults']:.1f} | {100 * r['visible']:.1f} "
              f"| {100 * r['lock']:.1f} | {100 * r['consequential']:.1f} | {100 * r['normal_flagged']:.1f} |")


if __name__ == "__main__":
    typer.run(main)
