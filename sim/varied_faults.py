"""Fault families of the varied task, each an `Effect` (or a sensor change) acting from `step` on.

| kind | what happens | value |
|---|---|---|
| `lock` | the paper's joint lock: overshoot, then the brake holds the joint | overshoot (deg) |
| `small_overshoot` | the joint overshoots its goal for one block, then follows the plan again | deg |
| `drift` | the joint's command drifts away from the plan | deg/s |
| `slip` | pads and cube turn slippery (friction drops) and the cube slides out | friction left |
| `gripper_open` | the gripper opens | - |
| `force_bias` | one finger force axis reads off by a bias (sensor fault) | N |
| `stray_post` | a post nobody reported stands in the path | - |
| `wrong_side` | the arm goes around the post on the side its position forbids | - |
| `wrong_cube` | the arm plans for a cube where it is not (stale perception) | offset (m) |

`step` is the observation step at which the fault starts. A stray post stands from the start;
its `step` is the step the arm would reach it, and the benchmark measures delay from the first
step at which the episode departs from its no-fault twin.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from dm_control import mjcf

from neural_asm.sim.channels import CHANNEL_NAMES
from neural_asm.sim.config import SIM
from neural_asm.sim.effects import Effect, Tick
from neural_asm.sim.faults import FaultSpec, JointLock
from neural_asm.sim.scene import SceneHandles

FAULT_KINDS: tuple[str, ...] = ("lock", "small_overshoot", "drift", "slip", "gripper_open", "force_bias",
                                "stray_post", "wrong_side", "wrong_cube")
PLAN_FAULTS = ("wrong_side", "wrong_cube")  # change the plan itself, not the execution
FORCE_CHANNELS = tuple(CHANNEL_NAMES.index(f"{side}_{axis}") for side in ("left", "right") for axis in ("fx", "fy", "fz"))


@dataclass(frozen=True)
class VariedFault:
    """One fault of the varied task (see the table above)."""

    kind: str
    step: int
    joint: int = 0  # 1..7 for joint faults; force channel index for force_bias
    value: float = 0.0
    direction: tuple[float, float] = (0.0, 0.0)  # wrong_cube: where the planned cube is, relative to the real one

    def __post_init__(self) -> None:
        if self.kind not in FAULT_KINDS:
            raise ValueError(f"fault kind must be one of {FAULT_KINDS}, got {self.kind!r}")
        if not 0 < self.step < SIM.varied.n_steps:
            raise ValueError(f"fault step must be in 1..{SIM.varied.n_steps - 1}, got {self.step}")

    def to_dict(self) -> dict:
        return {"kind": self.kind, "step": int(self.step), "joint": int(self.joint), "value": float(self.value),
                "direction": [float(v) for v in self.direction]}

    @classmethod
    def from_dict(cls, d: dict) -> "VariedFault":
        return cls(d["kind"], int(d["step"]), int(d["joint"]), float(d["value"]), tuple(d["direction"]))


class FaultEffect:
    """An effect driven by one ``VariedFault``, with nothing to set up after the reset."""

    def __init__(self, fault: VariedFault) -> None:
        self.fault = fault

    def initialize(self, physics: mjcf.Physics, scene: SceneHandles) -> None:
        pass


class SmallOvershoot(FaultEffect):
    """Joint `joint` overshoots by `value` deg on the way to step `step`, then returns to the plan."""

    def before_tick(self, physics: mjcf.Physics, scene: SceneHandles, tick: Tick) -> None:
        k, j = self.fault.step, self.fault.joint - 1
        frac = (tick.index - tick.step * SIM.timing.ticks_per_step + 1) / SIM.timing.ticks_per_step
        offset = np.deg2rad(self.fault.value)
        if tick.step == k - 1:
            tick.target[j] += frac * offset
        elif tick.step == k:
            tick.target[j] += (1.0 - frac) * offset


class Drift(FaultEffect):
    """Joint `joint`'s command drifts at `value` deg/s from step `step` on."""

    def before_tick(self, physics: mjcf.Physics, scene: SceneHandles, tick: Tick) -> None:
        start = SIM.timing.step_time(self.fault.step)
        elapsed = tick.time_s + 1.0 / SIM.timing.control_hz - start
        if elapsed > 0:
            tick.target[self.fault.joint - 1] += np.deg2rad(self.fault.value) * elapsed


def _grip_geoms(scene: SceneHandles) -> list:
    """The geoms whose friction holds the cube: both finger pads and the cube."""
    pads = [scene.panda.root.find("geom", f"{side}_pad") for side in ("left", "right")]
    return [*pads, *scene.cube_body.find_all("geom")]


class RestoreFriction:
    """Puts the grip's friction back to the model's (a slip in an earlier episode of this
    process changed the compiled model, which a reset does not undo)."""

    def initialize(self, physics: mjcf.Physics, scene: SceneHandles) -> None:
        for geom in _grip_geoms(scene):
            physics.bind(geom).friction = geom.friction

    def before_tick(self, physics: mjcf.Physics, scene: SceneHandles, tick: Tick) -> None:
        pass


class Slip(FaultEffect):
    """From step `step` on, pads and cube turn slippery (friction `value`): the cube slides out.

    MuJoCo takes the larger friction of two touching geoms, so both sides change."""

    def before_tick(self, physics: mjcf.Physics, scene: SceneHandles, tick: Tick) -> None:
        if tick.step >= self.fault.step:
            for geom in _grip_geoms(scene):
                physics.bind(geom).friction = [self.fault.value, 0.0, 0.0]


class GripperOpen(FaultEffect):
    """The gripper opens at step `step` and stays open."""

    def before_tick(self, physics: mjcf.Physics, scene: SceneHandles, tick: Tick) -> None:
        if tick.step >= self.fault.step:
            tick.gripper_closed = False


class PlacePost:
    """Stands a post (mocap body) at `xy` for the whole episode."""

    def __init__(self, index: int, xy: np.ndarray) -> None:
        self.index, self.xy = index, np.asarray(xy, float)

    def initialize(self, physics: mjcf.Physics, scene: SceneHandles) -> None:
        physics.bind(scene.posts[self.index]).mocap_pos = [*self.xy, 0.0]

    def before_tick(self, physics: mjcf.Physics, scene: SceneHandles, tick: Tick) -> None:
        pass


def execution_effects(fault: VariedFault | None) -> list[Effect]:
    """The effects that carry out a fault during execution (plan and sensor faults have none)."""
    if fault is None or fault.kind in (*PLAN_FAULTS, "force_bias", "stray_post"):
        return []
    if fault.kind == "lock":
        return [JointLock(FaultSpec(fault.joint, SIM.timing.step_time(fault.step), fault.value))]
    table = {"small_overshoot": SmallOvershoot, "drift": Drift, "slip": Slip, "gripper_open": GripperOpen}
    return [table[fault.kind](fault)]


def apply_sensor_fault(observations: np.ndarray, fault: VariedFault | None) -> np.ndarray:
    """Observations as a faulty sensor reports them (force bias does not change the physics)."""
    if fault is None or fault.kind != "force_bias":
        return observations
    out = observations.copy()
    out[fault.step:, fault.joint] += fault.value
    return out
