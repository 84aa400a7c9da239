"""Inverse kinematics for the tool centre point with mink, on an arm-only copy of the Panda.

A posture task pulls the redundant (null-space) degree of freedom towards a reference posture.
Without it, solving waypoint after waypoint lets the elbow drift differently in every episode
(5-20 degrees on joints 1, 3, 5, 7 in a prototype), which is not how a stereotyped, repeated
demonstration looks and hides small faults.
"""

from __future__ import annotations

from functools import cached_property

import mink
import numpy as np
from dm_control import mjcf

from neural_asm.sim.panda import build_panda


class IKError(RuntimeError):
    """The IK did not reach its target."""


class PandaIK:
    """Solve tool-centre-point poses for the 7 arm joints."""

    def __init__(self, posture_cost: float = 2e-3, tol_m: float = 5e-4, tol_rad: float = 5e-3,
                 max_iters: int = 60) -> None:
        self.posture_cost, self.tol_m, self.tol_rad, self.max_iters = posture_cost, tol_m, tol_rad, max_iters

    @cached_property
    def _model(self):
        return mjcf.Physics.from_mjcf_model(build_panda().root).model.ptr

    @cached_property
    def _solver(self) -> tuple:
        model = self._model
        config = mink.Configuration(model)
        frame = mink.FrameTask("tcp", "site", position_cost=1.0, orientation_cost=0.5, lm_damping=1e-4)
        posture = mink.PostureTask(model, cost=self.posture_cost)
        return config, frame, posture, [mink.ConfigurationLimit(model)]

    def solve(self, position: np.ndarray, rotation: np.ndarray, q_start: np.ndarray,
              q_posture: np.ndarray) -> np.ndarray:
        """Joint angles putting the TCP at `position` with orientation `rotation` (3x3)."""
        config, frame, posture, limits = self._solver
        config.update(np.concatenate([q_start, [0.04, 0.04]]))
        posture.set_target(np.concatenate([q_posture, [0.04, 0.04]]))
        frame.set_target(mink.SE3.from_rotation_and_translation(mink.SO3.from_matrix(rotation), position))
        for _ in range(self.max_iters):
            err = frame.compute_error(config)
            if np.linalg.norm(err[:3]) < self.tol_m and np.linalg.norm(err[3:]) < self.tol_rad:
                return config.q[:7].copy()
            velocity = mink.solve_ik(config, [frame, posture], 1.0, "daqp", damping=1e-4, limits=limits)
            config.integrate_inplace(velocity, 1.0)
        raise IKError(f"IK did not converge to {position} (error {np.linalg.norm(err[:3]):.2e} m)")
