"""Joint-lock faults: the paper's fault model and its 980-episode grid.

A fault (j, t, theta): during the 0.5 s block that ends at time t, joint j's servo is driven to
its desired goal for t plus theta (the overshoot); from t on its servo is stuck there and its
brake (a joint equality constraint, off in normal operation) holds it for the rest of the
episode, whatever the plan or a collision asks. The brake holds the joint where the overshoot
got it: goal + theta (clipped to the joint's range), unless a collision stopped it first (a
joint-2 overshoot near the table drives the hand into the table). So at observation step 2t
the joint reads goal + theta; a 0-degree overshoot shows only from the next step, as the joint
stops following the plan.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from dm_control import mjcf

from neural_asm.sim.config import SIM
from neural_asm.sim.effects import Tick
from neural_asm.sim.panda import Q_MAX, Q_MIN
from neural_asm.sim.scene import SceneHandles

GRID_JOINTS = tuple(range(1, 8))
GRID_TIMES_S = tuple(1.0 + 0.5 * i for i in range(10))  # 1.0 .. 5.5
GRID_OVERSHOOTS_DEG = (-15.0, -10.0, -5.0, 0.0, 5.0, 10.0, 15.0)


@dataclass(frozen=True)
class FaultSpec:
    """Joint `joint` (1..7) overshoots its goal by `overshoot_deg` at `time_s` and stays locked."""

    joint: int
    time_s: float
    overshoot_deg: float

    def __post_init__(self) -> None:
        if isinstance(self.joint, bool) or not isinstance(self.joint, (int, np.integer)):
            raise ValueError(f"joint must be an integer 1..7, got {self.joint!r}")
        if not 1 <= self.joint <= 7:
            raise ValueError(f"joint must be in 1..7, got {self.joint}")
        timing = SIM.timing
        last = timing.step_time(timing.n_steps - 1)
        if not isinstance(self.time_s, (int, float, np.number)) or not math.isfinite(self.time_s):
            raise ValueError(f"time_s must be a finite number, got {self.time_s!r}")
        step = self.time_s * timing.observation_hz
        if not (0 < self.time_s <= last and abs(step - round(step)) < 1e-9):
            raise ValueError(f"time_s must be on the {1 / timing.observation_hz:g} s observation grid "
                             f"within (0, {last:g}] s, got {self.time_s}")
        if not isinstance(self.overshoot_deg, (int, float, np.number)) or not math.isfinite(self.overshoot_deg):
            raise ValueError(f"overshoot_deg must be a finite number, got {self.overshoot_deg!r}")
        if abs(self.overshoot_deg) > 90:
            raise ValueError(f"overshoot_deg must be within +-90, got {self.overshoot_deg}")

    @property
    def step(self) -> int:
        """Observation step at which the joint has overshot (2t)."""
        return round(self.time_s * SIM.timing.observation_hz)

    def to_dict(self) -> dict:
        return {"joint": int(self.joint), "time_s": float(self.time_s), "overshoot_deg": float(self.overshoot_deg)}


def fault_grid(skills: tuple[str, ...] | None = None) -> list[tuple[str, FaultSpec]]:
    """The paper's 980 faults: 7 joints x 10 times x 7 overshoots x 2 skills."""
    if skills is None:
        from neural_asm.sim.skills import SKILLS

        skills = SKILLS
    return [(skill, FaultSpec(j, t, th)) for skill in skills for j in GRID_JOINTS
            for t in GRID_TIMES_S for th in GRID_OVERSHOOTS_DEG]


class JointLock:
    """The `Effect` that carries out a `FaultSpec`."""

    def __init__(self, spec: FaultSpec) -> None:
        self.spec = spec
        self.index = spec.joint - 1
        self.locked_value: float | None = None

    def initialize(self, physics: mjcf.Physics, scene: SceneHandles) -> None:
        self.locked_value = None
        for eq in scene.panda.lock_equalities:
            physics.bind(eq).active = False

    def before_tick(self, physics: mjcf.Physics, scene: SceneHandles, tick: Tick) -> None:
        k, j = self.spec.step, self.index
        goal = float(np.clip(tick.plan[k, j] + np.deg2rad(self.spec.overshoot_deg), Q_MIN[j], Q_MAX[j]))
        if tick.step == k - 1:  # the overshoot: drive towards goal + theta instead of goal
            block = SIM.timing.ticks_per_step
            frac = (tick.index - tick.step * block + 1) / block
            start = tick.plan[k - 1, j]
            tick.target[j] = start + frac * (goal - start)
            tick.velocity[j] = (goal - start) * SIM.timing.observation_hz
        elif tick.step >= k:  # locked where the overshoot got it: engaged brake, stuck servo
            if self.locked_value is None:
                self.locked_value = float(physics.bind(scene.panda.joints[j]).qpos[0])
                brake = physics.bind(scene.panda.lock_equalities[j])
                brake.data[0] = self.locked_value
                brake.active = True
            tick.target[j] = self.locked_value
            tick.velocity[j] = 0.0
