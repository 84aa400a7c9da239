"""Every rival by name behind the one `Detector` protocol, and the line-up each benchmark compares.

Each rival is fitted on normalised demonstrations with their true skills and the indices of
the context channels, and returns ``expected(x, skills)`` (N, T, D), causal in time (see
``rivals.base``); the z-scores also their ``spread``. Errors x - expected, energies and
thresholds are computed by the caller, the same way for every method.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from neural_asm.rivals.base import Detector, DetectorBase
from neural_asm.rivals.one_step import LinearOneStep, TemplateResidualOneStep
from neural_asm.rivals.sequence import LSTMVAE, GRUOneStep
from neural_asm.rivals.statistics import ClassicASM, PooledZScore
from neural_asm.rivals.templates import (ConditionalTemplate, CueNearestDemos, CueTemplate, LikelihoodTemplate,
                                         NearestDemos, PerSkillZScore, StepRidgeTemplate)

RIVALS: dict[str, type[DetectorBase]] = {rival.name: rival for rival in (
    PooledZScore, ClassicASM, PerSkillZScore, LikelihoodTemplate, ConditionalTemplate, CueTemplate, NearestDemos, CueNearestDemos,
    StepRidgeTemplate, LinearOneStep, TemplateResidualOneStep, GRUOneStep, LSTMVAE)}

Spec = tuple[str, dict[str, Any]]  # a rival's name in RIVALS and the options it is built with

LINE_UPS: dict[str, tuple[Spec, ...]] = {
    # The paper's fault sweep: its z-score baselines (pooled; per true skill; per recognised
    # skill, the classic ASM) and a one-step predictor of one past step at one ridge strength.
    "paper": (("zscore_pooled", {}), ("per_skill_zscore", {"name": "zscore_per_skill"}), ("classic_asm", {}),
              ("linear_one_step", {"lags": (1,), "ridges": (1e-2,), "poolings": (False,)})),
    # The varied task: every rival at its default hyper-parameters.
    "varied": (("per_skill_zscore", {}), ("conditional_template", {}), ("cue_template", {}),
               ("template_residual_one_step", {}), ("template_residual_one_step", {"template": StepRidgeTemplate}),
               ("nearest_demos", {}), ("cue_nearest_demos", {}), ("linear_one_step", {}), ("gru_one_step", {}),
               ("lstm_vae", {})),
}


def build(specs: Sequence[Spec]) -> list[Detector]:
    """One unfitted instance per spec."""
    return [RIVALS[name](**options) for name, options in specs]


def line_up(benchmark: str) -> list[Detector]:
    """The unfitted rivals `benchmark` (a key of LINE_UPS) compares the Neural ASM with."""
    return build(LINE_UPS[benchmark])
