"""What acts on an episode before each control tick (the composer "before_step" split).

The controller only tracks a plan; faults and disturbances are `Effect`s the runner calls
before every 40 Hz tick with a mutable `Tick`. An effect may rewrite the servo command for
this tick or change the physics (engage a brake, release an object); the controller never
branches on them.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np
from dm_control import mjcf

from neural_asm.sim.scene import SceneHandles


@dataclass
class Tick:
    """One control tick: its index and time, the plan, and the command about to be applied."""

    index: int  # 0 .. 299
    time_s: float  # time at the start of the tick
    step: int  # the observation block this tick belongs to (k: from t_k to t_k+1)
    plan: np.ndarray  # (15, 7) joint plan of the episode (rad)
    target: np.ndarray  # (7,) joint position command for the end of this tick (rad), mutable
    velocity: np.ndarray  # (7,) velocity feed-forward (rad/s), mutable
    gripper_closed: bool


class Effect(Protocol):
    """A fault or disturbance."""

    def initialize(self, physics: mjcf.Physics, scene: SceneHandles) -> None:
        """Called once after the episode's reset."""

    def before_tick(self, physics: mjcf.Physics, scene: SceneHandles, tick: Tick) -> None:
        """Called before every control tick."""
