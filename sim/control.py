"""Executing a skill memory's recalled plan, with or without its reactive correction.

A memory recalls the skill's sensorimotor sequence from the first observation (offline
recall); its joint channels are the plan, its gripper channel the gripper toggles
(`plan_from_recall`). The memory's 25 channels do not contain where the cube lies, so
`adapt_grasp` moves the grasp waypoints by the perceived cube offset, as the demonstrator's IK
did (the same TCP shift, solved from the recalled posture): without it a recalled plan grasps
the average cube and places off target by the cube's offset.

`PlanCorrection` is the reactive correction: the joint set-point sent to the controller is the
recalled plan plus an integral of the proprioceptive prediction error e = q_recalled - q,

    q*(t) = q_rec(t) + K_i I(t),    dI/dt = e - leak I,    |K_i I| <= i_max per joint,

so the arm is driven back onto what the memory expects rather than onto wherever a load holds
it. There is no proportional term on e: it would stiffen the compliant arm during the impact
itself (the hook runs at 40 Hz, the impact lasts milliseconds), which is what a compliant
controller is there to avoid; the integral only grows while the error persists (a box resting
on the arm, a load the gravity compensation does not know). The leak and the clip are
anti-windup. `SIM.correction` holds the gains.
"""

from __future__ import annotations

import numpy as np

from sim.channels import GRIPPER_CHANNEL, JOINT_CHANNELS
from sim.config import SIM, ControllerKind, CorrectionGains
from sim.disturbances import FallingObject
from sim.episode import Episode
from sim.panda import dh_forward
from sim.runner import ControlState, execute_plan, seed_variation
from sim.skills import shared_ik, skill_spec, waypoints


def plan_from_recall(recalled: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(T, 7) joint plan and (T,) 0/1 gripper toggles from a recalled (T, 25) sequence."""
    recalled = np.asarray(recalled, dtype=float)
    return recalled[:, JOINT_CHANNELS].copy(), (recalled[:, GRIPPER_CHANNEL] > 0.5).astype(float)


def adapt_grasp(joints: np.ndarray, skill: str, cube_xy: np.ndarray) -> np.ndarray:
    """Shift a skill's joint plan so that it grasps a cube at `cube_xy` instead of the nominal one.

    Each step's TCP moves by what the demonstrator's waypoints move for this cube (the grasp,
    the approach and half the way in and out of it), keeping the recalled orientation; the
    IK starts from and is pulled towards the recalled posture, so steps the cube does not
    concern are returned unchanged.
    """
    shift = waypoints(skill, np.asarray(cube_xy)) - waypoints(skill, np.asarray(skill_spec(skill).cube_xy))
    adapted = np.array(joints, dtype=float)
    for k in np.flatnonzero(np.abs(shift).max(axis=1) > 0):
        pose = dh_forward(adapted[k])
        adapted[k] = shared_ik().solve(pose[:3, 3] + shift[k], pose[:3, :3], adapted[k], joints[k])
    return adapted


class PlanCorrection:
    """Correction hook: q* = q_rec + K_i I, I the leaky, clipped integral of q_rec - q."""

    def __init__(self, gains: CorrectionGains = SIM.correction) -> None:
        self.gains = gains
        self.integral = np.zeros(7)
        self.previous: np.ndarray | None = None

    def __call__(self, state: ControlState) -> np.ndarray:
        g, dt = self.gains, 1.0 / SIM.timing.control_hz
        # ControlState.target is the plan at the END of this tick; the arm should be at the
        # previous tick's target now (else one tick of planned motion would count as error).
        reference = state.target if self.previous is None else self.previous
        self.previous = state.target.copy()
        self.integral = self.integral * (1.0 - g.leak * dt) + (reference - state.q) * dt
        bound = np.radians(g.i_max_deg) / g.ki
        self.integral = np.clip(self.integral, -bound, bound)
        return state.target + g.ki * self.integral


def execute_recalled(recalled: np.ndarray, skill: str, seed: int, corrected: bool,
                     controller: ControllerKind | None = None, disturbance: FallingObject | None = None,
                     gains: CorrectionGains = SIM.correction) -> Episode:
    """Execute a memory's recalled (15, 25) sequence for `seed`'s scene, grasp adapted to its cube.

    `corrected` adds `PlanCorrection`; `controller` defaults to `SIM.controller`. This is the
    one call a demo needs: recall from the episode's first observation, then this.
    """
    joints, gripper = plan_from_recall(recalled)
    joints = adapt_grasp(joints, skill, seed_variation(skill, seed).cube_xy)
    hook = PlanCorrection(gains) if corrected else None
    return execute_plan(joints, gripper, seed, correction_hook=hook, disturbance=disturbance, skill=skill,
                        controller=controller)
