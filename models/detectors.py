"""Baseline fault detectors, every one scored exactly as the Neural ASM: by what it expects.

Each detector is fitted on normalised demonstrations with their true skills and the indices
of the context channels, and returns ``expected(x, skills)`` (N, T, D), causal in time (see
``models.detector_base``). Errors x - expected, energies and thresholds are computed by the
caller, the same way for every method.
"""

from __future__ import annotations

from neural_asm.models.detector_base import Detector
from neural_asm.models.one_step import LinearOneStep, TemplateResidualOneStep
from neural_asm.models.sequence_detectors import LSTMVAE, GRUOneStep, RecurrentConfig
from neural_asm.models.templates import (ConditionalTemplate, CueNearestDemos, CueTemplate, NearestDemos, PerSkillZScore,
                              StepRidgeTemplate)

__all__ = [
    "Detector",
    "PerSkillZScore",
    "ConditionalTemplate",
    "CueTemplate",
    "CueNearestDemos",
    "TemplateResidualOneStep",
    "StepRidgeTemplate",
    "NearestDemos",
    "LinearOneStep",
    "GRUOneStep",
    "LSTMVAE",
    "RecurrentConfig",
    "all_detectors",
]


def all_detectors() -> list[Detector]:
    """One unfitted instance of every baseline, default hyper-parameters."""
    return [
        PerSkillZScore(),
        ConditionalTemplate(),
        CueTemplate(),
        TemplateResidualOneStep(),
        TemplateResidualOneStep(template=StepRidgeTemplate),
        NearestDemos(),
        CueNearestDemos(),
        LinearOneStep(),
        GRUOneStep(),
        LSTMVAE(),
    ]
