"""Executing a skill memory's recalled plan, with or without its reactive correction.

A memory recalls the skill's sensorimotor sequence from the first observation (offline
recall); its joint channels are the plan, its gripper channel the gripper toggles
(`plan_from_recall`). The memory's 25 channels contain neither where the cube lies nor where it
must go, and recalled joint angles put the tool within about 1 cm of the demonstrated one (the
success tolerance itself), so `anchor_plan` fixes the plan to the scene as the demonstrator's
IK did: the steps that must be exact (grasp and place) go exactly to the perceived cube and the
goal, the steps around the grasp move by the cube's offset, all solved from the recalled
posture. Without it a recalled plan grasps the average cube and places it 1-2 cm off target
in about one run in ten.

`PlanCorrection` is the reactive correction: the joint set-point sent to the controller is the
recalled plan plus an integral of the proprioceptive prediction error e = q_recalled - q,

    q*(t) = q_rec(t) + c(t),   c = clip(K_i I, +-min(i_max, |tau_ext| / K)),   dI/dt = e - leak I,

so the arm is driven back onto what the memory expects rather than onto wherever a load holds
it. The offset's torque K c never exceeds the external torque the arm feels at that joint
(`ControlState.external_torque`, what a torque-sensing arm such as the Panda estimates): the
correction holds the arm up against a load, and when the load goes (a box sliding off the
forearm) the offset goes with it in the same tick, instead of springing the hand up by the
offset while the integral unwinds. With a `detector` (the memory's monitor: does the energy of
the observations so far say something is wrong?) the correction stays off until the monitor
has kept flagging for a time chosen per observation rate (`sim.config.CONFIRM_S`: at 2 Hz two
observations in a row, at 40 Hz one second), and the arm is a plain compliant arm until then: one flag may be a false alarm, or a blow that is already over,
and a correction engaged at once would hold a heavy box on the arm that would have slid off.
A joint at 90 % of its torque limit for 0.1 s is holding a load the arm should not hold, which
on a collaborative arm may be a person: the correction lets go for the rest of the episode (or
never engages, if the arm was there before the monitor flagged), its offset decaying within
~0.1 s rather than in one tick (a set-point step under a heavy load slams the hand down), and
the arm yields as the compliant controller alone would. There is no proportional term on e:
it would stiffen the compliant arm during the impact itself (the hook runs at 40 Hz, the impact
lasts milliseconds), which is what a compliant controller is there to avoid; the integral only
grows while the error persists (a box resting on the arm, a load the gravity compensation does
not know). The leak, the clip and the torque bound are anti-windup. `SIM.correction` holds the
gains.
"""

from __future__ import annotations

from typing import Callable

import numpy as np

from neural_asm.sim.channels import GRIPPER_CHANNEL, JOINT_CHANNELS
from neural_asm.sim.config import SIM, CorrectionGains
from neural_asm.sim.episode import Episode
from neural_asm.sim.panda import TAU_MAX, dh_forward
from neural_asm.sim.paper import Job, execute_plan, seed_variation
from neural_asm.sim.runner import N_JOINTS, ControlState
from neural_asm.sim.skills import DOWN, PRECISE_STEPS, shared_ik, skill_spec, waypoints

Detector = Callable[[np.ndarray], bool]  # observations so far (k + 1, 25) -> fault at observation k?


def plan_from_recall(recalled: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(T, 7) joint plan and (T,) 0/1 gripper toggles from a recalled (T, 25) sequence."""
    recalled = np.asarray(recalled, dtype=float)
    return recalled[:, JOINT_CHANNELS].copy(), (recalled[:, GRIPPER_CHANNEL] > 0.5).astype(float)


def anchor_plan(joints: np.ndarray, skill: str, cube_xy: np.ndarray) -> np.ndarray:
    """Fix a skill's recalled joint plan to a scene whose cube lies at `cube_xy`.

    The grasp and place steps (`PRECISE_STEPS`) go exactly to the demonstrator's waypoints for
    this cube, tool pointing down; the other steps' TCP moves by what the waypoints move for
    this cube (the approach and half the way in and out of it), keeping the recalled
    orientation. Each IK starts from and is pulled towards the recalled posture, so steps
    neither concerns (the start) are returned unchanged.
    """
    scene = waypoints(skill, np.asarray(cube_xy))
    shift = scene - waypoints(skill, np.asarray(skill_spec(skill).cube_xy))
    anchored = np.array(joints, dtype=float)
    for k in range(len(anchored)):
        pose = dh_forward(anchored[k])
        if k in PRECISE_STEPS:
            anchored[k] = shared_ik().solve(scene[k], DOWN, anchored[k], joints[k])
        elif np.abs(shift[k]).max() > 0:
            anchored[k] = shared_ik().solve(pose[:3, 3] + shift[k], pose[:3, :3], anchored[k], joints[k])
    return anchored


class PlanCorrection:
    """Correction hook: q* = q_rec + K_i I, I the leaky, clipped integral of q_rec - q, its
    torque bounded by the external torque; with a `detector` of observations made at `rate` Hz,
    engaged once its flags have kept coming, each within `gains.confirm_at(rate)` of the last, for
    that time. `engaged_step` and `yielded_step` count observations (at 2 Hz the skill layer's
    steps, at 40 Hz the ticks), as the monitor's flags do."""

    def __init__(self, gains: CorrectionGains = SIM.correction, detector: Detector | None = None,
                 rate: float = SIM.timing.observation_hz) -> None:
        self.gains, self.detector = gains, detector
        self.integral = np.zeros(N_JOINTS)
        self.previous: np.ndarray | None = None
        self.engaged_step: int | None = None if detector is not None else 0
        self.seen = 0
        self.tick = 0  # control ticks so far: observations are timed by them, at any rate
        self.confirm_ticks = round(gains.confirm_at(rate) * SIM.timing.control_hz)
        self.flagged_since: int | None = None  # tick of the first flag of the flags still coming
        self.last_flag = 0  # tick of the latest flag
        self.loaded_s = 0.0  # how long a joint has been at the yield torque, engaged or not
        self.overloaded = False
        self.yielded_step: int | None = None
        self.offset = np.zeros(N_JOINTS)  # the last set-point offset sent (decays once let go)

    def __call__(self, state: ControlState) -> np.ndarray:
        g, dt = self.gains, 1.0 / SIM.timing.control_hz
        # ControlState.target is the plan at the END of this tick; the arm should be at the
        # previous tick's target now (else one tick of planned motion would count as error).
        reference = state.target if self.previous is None else self.previous
        self.previous = state.target.copy()
        loaded = (np.abs(state.torque) >= g.yield_torque * TAU_MAX).any()
        self.loaded_s = self.loaded_s + dt if loaded else 0.0
        self.overloaded |= g.yield_s is not None and self.loaded_s >= g.yield_s
        self.tick += 1
        if self.engaged_step is None and len(state.observations) > self.seen:
            self.seen = len(state.observations)
            self._confirm(bool(self.detector(state.observations)))
        if self.engaged_step is None:
            return state.target
        if self.overloaded and self.yielded_step is None:
            self.yielded_step = len(state.observations) - 1
        if self.yielded_step is not None:
            self.offset = self.offset * np.exp(-dt / g.release_s)
            return state.target + self.offset
        self.integral = self.integral * (1.0 - g.leak * dt) + (reference - state.q) * dt
        bound = np.radians(g.i_max_deg) / g.ki
        self.integral = np.clip(self.integral, -bound, bound)
        held = np.minimum(np.radians(g.i_max_deg), np.abs(state.external_torque) / state.stiffness)
        self.offset = np.clip(g.ki * self.integral, -held, held)
        return state.target + self.offset

    def _confirm(self, flagged: bool) -> None:
        """Engage once flags have kept coming for the confirmation time, none further apart."""
        if flagged:
            if self.flagged_since is None:
                self.flagged_since = self.tick
            self.last_flag = self.tick
            if self.tick - self.flagged_since >= self.confirm_ticks:
                self.engaged_step = self.seen - 1
        elif self.flagged_since is not None and self.tick - self.last_flag >= self.confirm_ticks:
            self.flagged_since = None


def execute_recalled(recalled: np.ndarray, job: Job, correction: PlanCorrection | None = None) -> Episode:
    """Execute a memory's recalled (15, 25) sequence (the skill layer's 2 Hz steps) as `job`'s
    episode (its scene, fault, disturbance, controller and rate), anchored to its cube and goal.

    `correction` (a fresh `PlanCorrection` per run; None: uncorrected) is the tick hook, and the
    caller keeps it to read when it engaged or let go. This is the one call a demo needs:
    recall from the episode's first observation, then this.
    """
    joints, gripper = plan_from_recall(recalled)
    joints = anchor_plan(joints, job.skill, seed_variation(job.skill, job.seed).cube_xy)
    return execute_plan(joints, gripper, job, correction)
