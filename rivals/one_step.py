"""Linear one-step rivals: of the observation itself, or of a conditional template's residual.

- ``LinearOneStep``: x[t+1] ridge-regressed on [x[t], ..., x[t-L+1], 1]
  (``models.one_step.fit_one_step``: L, the ridge strength and the pooling over skills chosen by
  cross-validation over whole demonstrations among the choices it is given; the paper sweep
  gives it one, L = 1 and ridge 0.01 pooled).
- ``TemplateResidualOneStep``: the conditional template plus a ridge prediction of its
  residual r[t+1] from r[t], ..., r[t-L+1]; the template absorbs what the context explains,
  the one-step model what the episode has shown so far (e.g. a speed or offset the context
  does not give).
"""

from __future__ import annotations

import numpy as np

from neural_asm.models.one_step import ONE_STEP_LAGS, ONE_STEP_RIDGES, POOLINGS, fit_one_step
from neural_asm.rivals.base import DetectorBase
from neural_asm.rivals.templates import ConditionalTemplate, StepRidgeTemplate


class LinearOneStep(DetectorBase):
    name = "linear_one_step"
    label = "linear one-step predictor (ridge)"

    def __init__(self, lags: tuple[int, ...] = ONE_STEP_LAGS, ridges: tuple[float, ...] = ONE_STEP_RIDGES,
                 poolings: tuple[bool, ...] = POOLINGS, name: str | None = None) -> None:
        super().__init__(name)
        self.choices = (lags, ridges, poolings)

    def _fit(self, x: np.ndarray, skills: np.ndarray, seed: int) -> None:
        self.one_step = fit_one_step(x, skills, seed, *self.choices)

    def _expected(self, x: np.ndarray, skills: np.ndarray) -> np.ndarray:
        return np.concatenate([x[:, :1], self.one_step.predict(x, skills)], axis=1)


class TemplateResidualOneStep(DetectorBase):
    name = "template_residual_one_step"
    label = "conditional template + one-step residual predictor"

    def __init__(self, residual_weight: float = 1.0, template: type[ConditionalTemplate | StepRidgeTemplate]
                 = ConditionalTemplate, name: str | None = None) -> None:
        """``residual_weight`` scales the residual's prediction: 1 is the baseline, 0 the template
        alone (lab/plan_probe.py measures what lies between). With ``template=
        StepRidgeTemplate`` it is plan recall without the network, the rival
        `step_ridge_template_residual`."""
        super().__init__(name)
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
