"""Two pick-and-place skills: end-effector waypoints -> IK (mink) -> a 2 Hz joint plan.

The skills start from different poses (the first observation alone tells them apart, which
offline recall needs) and move the cube in opposite directions across the table. A demonstration
is generated the way the paper describes (waypoints per 2 Hz step, joint angles by IK), as a
proxy for teleoperation. Per-seed variation (see `sim.config.Noise`): the cube's start pose,
the operator's start posture, and small tremor on the free-space waypoints. Each waypoint's IK
starts from the previous solution and is pulled towards the skill's nominal plan in the null
space, so repeated demonstrations stay stereotyped.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from neural_asm.sim.config import SIM
from neural_asm.sim.ik import PandaIK
from neural_asm.sim.panda import DQ_MAX
from neural_asm.sim.scene import CUBE_HALF

SKILLS: tuple[str, ...] = ("pick_left_place_right", "pick_right_place_left")
DOWN = np.diag([1.0, -1.0, -1.0])  # TCP pointing down, fingers closing along world y
HOVER, APPROACH, CARRY = 0.15, 0.05, 0.20  # heights above the grasp / place point (m)
# Steps at which the hand must be exactly at the grasp or place point (no waypoint tremor).
PRECISE_STEPS = (4, 5, 6, 11, 12)


@dataclass(frozen=True)
class SkillSpec:
    name: str
    start_tcp: tuple[float, float, float]
    cube_xy: tuple[float, float]
    target_xy: tuple[float, float]
    home: tuple[float, ...]  # reference posture for the IK's null space


SKILL_SPECS = {
    "pick_left_place_right": SkillSpec("pick_left_place_right", (0.30, 0.30, 0.45), (0.45, 0.20), (0.50, -0.20),
                                       (0.3, -0.3, 0.0, -2.4, 0.0, 2.1, 0.785)),
    "pick_right_place_left": SkillSpec("pick_right_place_left", (0.50, -0.35, 0.28), (0.55, -0.15), (0.40, 0.25),
                                       (-0.3, 0.0, 0.0, -2.2, 0.0, 2.2, 0.785)),
}
GRIPPER_PLAN = np.array([0, 0, 0, 0, 0, 1, 1, 1, 1, 1, 1, 1, 0, 0, 0], dtype=float)


class PlanError(RuntimeError):
    """A plan breaks the Panda's joint velocity limits."""


@dataclass(frozen=True)
class Variation:
    """Everything a seed changes before the episode runs."""

    cube_xy: np.ndarray  # (2,)
    cube_yaw: float
    start_noise: np.ndarray  # (7,) rad
    waypoint_noise: np.ndarray  # (15, 3) m


@dataclass(frozen=True)
class Plan:
    joints: np.ndarray  # (15, 7) rad, the desired angle at each observation time
    gripper: np.ndarray  # (15,) 0/1
    tcp: np.ndarray  # (15, 3) waypoints


def skill_spec(skill: str) -> SkillSpec:
    if skill not in SKILL_SPECS:
        raise ValueError(f"skill must be one of {SKILLS}, got {skill!r}")
    return SKILL_SPECS[skill]


def target_position(skill: str) -> np.ndarray:
    """Where the cube's centre should end up."""
    return np.array([*skill_spec(skill).target_xy, CUBE_HALF])


def sample_variation(skill: str, rng: np.random.Generator) -> Variation:
    """Draw a seed's variation (always the same number of draws, so later draws line up)."""
    noise = SIM.noise
    spec = skill_spec(skill)
    offset = rng.uniform(-noise.cube_xy_m, noise.cube_xy_m, 2)
    yaw = rng.uniform(-noise.cube_yaw_rad, noise.cube_yaw_rad)
    start = rng.normal(0.0, noise.start_joint_rad, 7)
    tremor = rng.normal(0.0, noise.waypoint_m, (SIM.timing.n_steps, 3))
    tremor[[0, *PRECISE_STEPS]] = 0.0
    return Variation(np.asarray(spec.cube_xy) + offset, float(yaw), start, tremor)


def waypoints(skill: str, cube_xy: np.ndarray) -> np.ndarray:
    """(15, 3) TCP waypoints, one per observation step, for a cube at `cube_xy`."""
    spec = skill_spec(skill)
    grasp = np.array([*cube_xy, CUBE_HALF])
    place = target_position(skill) + [0.0, 0.0, 0.002]
    up = np.array([0.0, 0.0, 1.0])
    start = np.asarray(spec.start_tcp)
    carry = 0.5 * (grasp + place) + CARRY * up
    return np.array([
        start, 0.5 * (start + grasp + HOVER * up), grasp + HOVER * up, grasp + APPROACH * up, grasp,
        grasp, grasp, grasp + HOVER * up, carry, place + HOVER * up, place + APPROACH * up,
        place, place, place + 0.10 * up, place + HOVER * up,
    ])


@lru_cache(maxsize=None)
def shared_ik() -> PandaIK:
    return PandaIK()


def _solve_sequence(tcp: np.ndarray, q_start: np.ndarray, postures: np.ndarray) -> np.ndarray:
    q = [q_start]
    for k in range(1, len(tcp)):
        q.append(shared_ik().solve(tcp[k], DOWN, q[-1], postures[k]))
    return np.array(q)


@lru_cache(maxsize=None)
def nominal_plan(skill: str) -> np.ndarray:
    """The skill's noise-free joint plan (15, 7): the null-space reference for every seed."""
    spec = skill_spec(skill)
    home = np.asarray(spec.home)
    tcp = waypoints(skill, np.asarray(spec.cube_xy))
    q0 = shared_ik().solve(np.asarray(spec.start_tcp), DOWN, home, home)
    plan = _solve_sequence(tcp, q0, np.tile(home, (len(tcp), 1)))
    plan.flags.writeable = False
    return plan


def check_velocity(joints: np.ndarray, margin: float = 0.9) -> None:
    """Raise `PlanError` if any block needs more than `margin` of a joint's velocity limit."""
    speed = np.abs(np.diff(joints, axis=0)) * SIM.timing.observation_hz
    worst = speed / DQ_MAX
    if worst.max() > margin:
        k, j = np.unravel_index(worst.argmax(), worst.shape)
        raise PlanError(f"joint {j + 1} needs {speed[k, j]:.2f} rad/s in block {k} (limit {DQ_MAX[j]})")


def make_plan(skill: str, variation: Variation) -> Plan:
    """The seed's plan: the varied start posture, then IK of the varied waypoints."""
    nominal = nominal_plan(skill)
    tcp = waypoints(skill, variation.cube_xy) + variation.waypoint_noise
    joints = _solve_sequence(tcp, nominal[0] + variation.start_noise, nominal)
    check_velocity(joints)
    return Plan(joints, GRIPPER_PLAN.copy(), tcp)
