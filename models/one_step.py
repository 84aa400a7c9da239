"""Linear one-step predictors: of the observation itself, or of a conditional template's residual.

- ``LinearOneStep``: x[t+1] ridge-regressed on [x[t], 1] (``models.baselines.LinearOneStep``).
- ``TemplateResidualOneStep``: the conditional template plus a ridge prediction of its
  residual r[t+1] from r[t]; the template absorbs what the context explains, the one-step
  model what the episode has shown so far (e.g. a speed or offset the context does not give).

Both choose, by 5-fold cross-validation over whole demonstrations, the ridge strength and
whether one model serves every skill or each skill has its own.
"""

from __future__ import annotations

import numpy as np

from models.baselines import LinearOneStep as RidgeOneStep
from models.detector_base import DetectorBase, episode_folds
from models.templates import ConditionalTemplate

ONE_STEP_RIDGES = (1e-3, 1e-2, 1e-1, 1.0, 10.0, 100.0, 1000.0)


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


def fit_one_step(x: np.ndarray, skills: np.ndarray, seed: int) -> dict[str, RidgeOneStep]:
    """Per-skill one-step models, ridge and pooling chosen by held-out one-step error."""
    folds = episode_folds(skills, seed)
    best, choice = np.inf, (ONE_STEP_RIDGES[0], False)
    for per_skill in (False, True):
        for ridge in ONE_STEP_RIDGES:
            error = 0.0
            for train, test in folds:
                models = _fit_models(x[train], skills[train], ridge, per_skill)
                error += ((_next_step_predictions(models, x[test], skills[test]) - x[test, 1:]) ** 2).sum()
            if error < best:
                best, choice = error, (ridge, per_skill)
    return _fit_models(x, skills, *choice)


class LinearOneStep(DetectorBase):
    name = "linear_one_step"
    label = "linear one-step predictor (ridge)"

    def _fit(self, x: np.ndarray, skills: np.ndarray, seed: int) -> None:
        self.models = fit_one_step(x, skills, seed)

    def _expected(self, x: np.ndarray, skills: np.ndarray) -> np.ndarray:
        return np.concatenate([x[:, :1], _next_step_predictions(self.models, x, skills)], axis=1)


class TemplateResidualOneStep(DetectorBase):
    name = "template_residual_one_step"
    label = "conditional template + one-step residual predictor"

    def _fit(self, x: np.ndarray, skills: np.ndarray, seed: int) -> None:
        self.template = ConditionalTemplate().fit(x, skills, self.context_channels, seed)
        residuals = self.template.cross_fitted_residuals(x, skills, seed)
        self.models = fit_one_step(residuals, skills, seed)

    def _expected(self, x: np.ndarray, skills: np.ndarray) -> np.ndarray:
        template = self.template.expected(x, skills)
        residuals = x - template
        correction = np.zeros_like(x)
        correction[:, 1:] = _next_step_predictions(self.models, residuals, skills)
        return template + correction
