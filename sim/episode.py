"""The record of one episode: observations for the model (2 Hz, or 40 Hz: every tick), 40 Hz
traces for the eyes."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from neural_asm.sim.channels import CHANNEL_NAMES, JOINT_CHANNELS
from neural_asm.sim.config import SIM
from neural_asm.sim.disturbances import FallingObject
from neural_asm.sim.faults import FaultSpec

if TYPE_CHECKING:
    from neural_asm.sim.varied_faults import VariedFault


@dataclass
class Episode:
    """One run of a skill. `observations[k]` is taken at t = k / `rate_hz` s (paper task: k = 0..14
    at 2 Hz, 0..299 at 40 Hz)."""

    observations: np.ndarray  # (T, D) float64, channels in `channel_names` order (paper task: (15, 25) or (300, 25))
    skill: str
    seed: int
    fault: "FaultSpec | VariedFault | None"
    disturbance: FallingObject | None
    success: bool  # cube centre within 1 cm of its target at t = 7.5 s
    cube_error_m: float
    plan: np.ndarray  # (15, 7) the joint plan that was executed (rad)
    t_hi: np.ndarray  # (301,) s, 40 Hz from t = 0 to 7.5
    qpos_hi: np.ndarray  # (301, 7) measured joint angles
    command_hi: np.ndarray  # (301, 7) joint targets applied to the servos (after faults/hook)
    ee_hi: np.ndarray  # (301, 3) tool centre point
    cube_hi: np.ndarray  # (301, 3) cube centre
    box_hi: np.ndarray  # (301, 3) falling box centre
    channel_names: tuple[str, ...] = CHANNEL_NAMES
    warnings: list[str] = field(default_factory=list)
    task: dict | None = None  # the varied task's context of this episode (sim.varied.Context.to_dict)
    rate_hz: float = SIM.timing.observation_hz  # the observation rate (sim.config.RATES)

    @property
    def joints(self) -> np.ndarray:
        """(T, 7) joint channels."""
        return self.observations[:, JOINT_CHANNELS]
