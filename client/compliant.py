"""Compliant control in the client: the memory's recalled plan under joint impedance, corrected
or not, and the service's monitor that gates the correction.

The correction must engage when the service flags the hit, so the gate is the service's own
decision computed here: the served model (the same checkpoint, digest checked), its
calibration, rate and threshold kind, stepped as a session steps (``SkillStream``). The
episode is simulated before it is streamed, so the service then flags the same steps.
"""

from __future__ import annotations

import numpy as np

from experiments.correction.pipeline import recall
from models.asm import NeuralASM, step_streams
from models.fault import ThresholdKind
from sim.config import SIM
from sim.control import PlanCorrection, execute_recalled
from sim.disturbances import FallingObject
from sim.episode import Episode
from sim.faults import FaultSpec


class ServedMonitor:
    """The service's fault decision per observation (the `Detector` `PlanCorrection` waits for)."""

    def __init__(self, model: NeuralASM, mode: str, fpr: float, threshold: ThresholdKind = "episode") -> None:
        self.stream = model.stream(mode, 1, weighted=True, fpr=fpr, threshold=threshold)
        self.flags: list[bool] = []

    def __call__(self, observations: np.ndarray) -> bool:
        for x in observations[len(self.flags):]:
            [step] = step_streams([self.stream], np.asarray(x, np.float64)[None])
            self.flags.append(bool(step is not None and step.decision is not None and step.decision.fault))
        return self.flags[-1]


def compliant_episode(model: NeuralASM, skill: str, seed: int, hit: FallingObject | None, fault: FaultSpec | None,
                      corrected: bool, mode: str, fpr: float) -> tuple[Episode, PlanCorrection | None]:
    """The memory's plan recalled from the first observation, executed under compliant control;
    with `corrected`, the correction engages once the served monitor has flagged `SIM.correction.confirm`
    observations in a row."""
    correction = PlanCorrection(SIM.correction, ServedMonitor(model, mode, fpr)) if corrected else None
    episode = execute_recalled(recall(model, skill, seed), skill, seed, correction, "compliant", hit, fault)
    return episode, correction
