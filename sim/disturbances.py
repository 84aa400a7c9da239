"""A falling object that hits the arm mid-episode (the paper's reactive-correction scenario).

The box hovers out of reach behind the robot. At `release_s` it is placed `drop_height_m` above
the current position of the target link and thrown down at `speed_m_s`, so it hits the arm
wherever the skill has taken it. With gravity-compensated, moderately stiff servos a 5 kg box at
4 m/s deflects the hand by 7-9 cm (measured in tests and sim/README.md).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from dm_control import mjcf

from neural_asm.sim.config import SIM
from neural_asm.sim.effects import Tick
from neural_asm.sim.scene import BOX_HALF, SceneHandles


@dataclass(frozen=True)
class FallingObject:
    """A box of `mass_kg` released above link `target_link` (5 = forearm, 7 = wrist) at `release_s`."""

    release_s: float = 4.0
    drop_height_m: float = 0.15
    speed_m_s: float = 4.0
    mass_kg: float = 5.0
    target_link: int = 6

    def __post_init__(self) -> None:
        for name in ("release_s", "drop_height_m", "speed_m_s", "mass_kg"):
            value = getattr(self, name)
            if not isinstance(value, (int, float, np.number)) or not math.isfinite(value):
                raise ValueError(f"{name} must be a finite number, got {value!r}")
        if not 0 <= self.release_s < SIM.timing.duration_s:
            raise ValueError(f"release_s must be within [0, {SIM.timing.duration_s:g}) s, got {self.release_s}")
        if self.drop_height_m <= 0 or self.mass_kg <= 0 or self.speed_m_s < 0:
            raise ValueError("drop_height_m and mass_kg must be > 0 and speed_m_s >= 0")
        if self.target_link not in range(1, 8):
            raise ValueError(f"target_link must be in 1..7, got {self.target_link}")

    def to_dict(self) -> dict:
        return {"kind": "falling_object", "release_s": self.release_s, "drop_height_m": self.drop_height_m,
                "speed_m_s": self.speed_m_s, "mass_kg": self.mass_kg, "target_link": self.target_link}


class FallingObjectEffect:
    """The `Effect` that drops the box."""

    def __init__(self, spec: FallingObject) -> None:
        self.spec = spec
        self.released = False

    def initialize(self, physics: mjcf.Physics, scene: SceneHandles) -> None:
        self.released = False

    def before_tick(self, physics: mjcf.Physics, scene: SceneHandles, tick: Tick) -> None:
        if self.released or tick.time_s + 1e-9 < self.spec.release_s:
            return
        self.released = True
        body = physics.bind(scene.box_body)  # mass changes only now: until release the run is the twin's
        hx, hy, hz = BOX_HALF
        body.mass = self.spec.mass_kg
        body.gravcomp = 0.0
        body.inertia = np.array([hy**2 + hz**2, hx**2 + hz**2, hx**2 + hy**2]) * self.spec.mass_kg / 3
        link = scene.panda.root.find("body", f"link{self.spec.target_link}")
        above = physics.bind(link).xpos + np.array([0.0, 0.0, self.spec.drop_height_m + BOX_HALF[2]])
        box = physics.bind(scene.box)
        box.qpos = np.concatenate([above, [1.0, 0.0, 0.0, 0.0]])
        box.qvel = np.array([0.0, 0.0, -self.spec.speed_m_s, 0.0, 0.0, 0.0])


def make_effect(spec: FallingObject | None) -> list[FallingObjectEffect]:
    """Effects for an optional disturbance spec."""
    return [] if spec is None else [FallingObjectEffect(spec)]


def elbow_hit(momentum_kg_m_s: float, speed_m_s: float = SIM.hit.speed_m_s, release_s: float = SIM.hit.release_s,
              drop_height_m: float = SIM.hit.drop_height_m) -> FallingObject:
    """A box dropped just above the elbow (link 4) during the carry, its mass setting the momentum.

    The reactive-correction experiment's hit family: from about 30 kg m/s the box comes to rest
    on the forearm on some skills, which a compliant arm gives way to (load / stiffness).
    """
    if not speed_m_s > 0:
        raise ValueError(f"speed_m_s must be > 0, got {speed_m_s}")
    return FallingObject(release_s=release_s, drop_height_m=drop_height_m, speed_m_s=speed_m_s,
                         mass_kg=momentum_kg_m_s / speed_m_s, target_link=4)
