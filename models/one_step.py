"""Linear one-step predictors: of the observation itself, or of a conditional template's residual.

- ``LinearOneStep``: x[t+1] ridge-regressed on [x[t], ..., x[t-L+1], 1]
  (``models.baselines.LinearOneStep`` on delay-embedded sequences).
- ``TemplateResidualOneStep``: the conditional template plus a ridge prediction of its
  residual r[t+1] from r[t], ..., r[t-L+1]; the template absorbs what the context explains,
  the one-step model what the episode has shown so far (e.g. a speed or offset the context
  does not give).

Both choose, by 5-fold cross-validation over whole demonstrations, the ridge strength, how
many past steps L they read (one step knows where the arm is, two also how fast it moves:
on the varied task two steps halve the held-out joint error), and whether one model serves
every skill or each skill has its own.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from neural_asm.models.baselines import LinearOneStep as RidgeOneStep
from neural_asm.models.detector_base import DetectorBase, episode_folds
from neural_asm.models.templates import ConditionalTemplate, StepRidgeTemplate

ONE_STEP_RIDGES = (1e-3, 1e-2, 1e-1, 1.0, 10.0, 100.0, 1000.0)
ONE_STEP_LAGS = (1, 2, 3)


def delay_embed(x: np.ndarray, lags: int) -> np.ndarray:
    """(N, T, D) -> (N, T, lags * D): each step followed by the lags - 1 steps before it, the
    first step standing in for the steps before the start (the embedding stays causal)."""
    parts = [x] + [np.concatenate([np.repeat(x[:, :1], j, axis=1), x[:, :-j]], axis=1) for j in range(1, lags)]
    return np.concatenate(parts, axis=2)


@dataclass(frozen=True)
class OneStep:
    """Ridge one-step models per skill over `lags` past steps."""

    models: dict[str, RidgeOneStep]
    lags: int

    def predict(self, x: np.ndarray, skills: np.ndarray) -> np.ndarray:
        """(N, T-1, D) predictions of steps 1..T-1, each from the steps before it."""
        return _next_step_predictions(self.models, delay_embed(x, self.lags), skills)[..., : x.shape[2]]


def _fit_models(x: np.ndarray, skills: np.ndarray, ridge: float, per_skill: bool) -> dict[str, RidgeOneStep]:
    names = np.unique(skills)
    if per_skill:
        return {s: RidgeOneStep.fit(x[skills == s], ridge) for s in names}
    pooled = RidgeOneStep.fit(x, ridge)
    return {s: pooled for s in names}


def _next_step_predictions(models: dict[str, RidgeOneStep], x: np.ndarray, skills: np.ndarray) -> np.ndarray:
    """(N, T-1, D) predictions of steps 1..T-1, each from the step before."""
    out = np.empty((len(x), x.shape[1] - 1, x.shape[2]))
    for s in np.unique(skills):
        rows = skills == s
        out[rows] = models[s].step(x[rows, :-1])
    return out


def fit_one_step(x: np.ndarray, skills: np.ndarray, seed: int, lag_choices: tuple[int, ...] = ONE_STEP_LAGS) -> OneStep:
    """Per-skill one-step models; past steps, ridge and pooling chosen by held-out one-step error."""
    folds = episode_folds(skills, seed)
    width = x.shape[2]
    best, choice = np.inf, (lag_choices[0], ONE_STEP_RIDGES[0], False)
    for lags in lag_choices:
        embedded = delay_embed(x, lags)
        for per_skill in (False, True):
            for ridge in ONE_STEP_RIDGES:
                error = 0.0
                for train, test in folds:
                    models = _fit_models(embedded[train], skills[train], ridge, per_skill)
                    predicted = _next_step_predictions(models, embedded[test], skills[test])[..., :width]
                    error += ((predicted - x[test, 1:]) ** 2).sum()
                if error < best:
                    best, choice = error, (lags, ridge, per_skill)
    lags, ridge, per_skill = choice
    return OneStep(_fit_models(delay_embed(x, lags), skills, ridge, per_skill), lags)


class LinearOneStep(DetectorBase):
    name = "linear_one_step"
    label = "linear one-step predictor (ridge)"

    def _fit(self, x: np.ndarray, skills: np.ndarray, seed: int) -> None:
        self.one_step = fit_one_step(x, skills, seed)

    def _expected(self, x: np.ndarray, skills: np.ndarray) -> np.ndarray:
        return np.concatenate([x[:, :1], self.one_step.predict(x, skills)], axis=1)


class TemplateResidualOneStep(DetectorBase):
    name = "template_residual_one_step"
    label = "conditional template + one-step residual predictor"

    def __init__(self, residual_weight: float = 1.0, template: type[ConditionalTemplate | StepRidgeTemplate]
                 = ConditionalTemplate) -> None:
        """``residual_weight`` scales the residual's prediction: 1 is the baseline, 0 the template
        alone (lab/plan_probe.py measures what lies between). With ``template=
        StepRidgeTemplate`` it is plan recall without the network, the rival
        `step_ridge_template_residual`."""
        super().__init__()
        self.residual_weight, self.template_class = residual_weight, template
        if template is StepRidgeTemplate:
            self.name = "step_ridge_template_residual"
            self.label = "one-ridge conditional template + one-step residual predictor"

    def _fit(self, x: np.ndarray, skills: np.ndarray, seed: int) -> None:
        self.template = self.template_class().fit(x, skills, self.context_channels, seed)
        residuals = self.template.cross_fitted_residuals(x, skills, seed)
        self.one_step = fit_one_step(residuals, skills, seed)

    def _expected(self, x: np.ndarray, skills: np.ndarray) -> np.ndarray:
        template = self.template.expected(x, skills)
        residuals = x - template
        correction = np.zeros_like(x)
        correction[:, 1:] = self.one_step.predict(residuals, skills)
        return template + self.residual_weight * correction
