"""Every constant of the simulation in one typed place.

Timing follows the paper's "Robot simulation details": a 40 Hz position controller under a
2 Hz skill layer, 15 observations (7.5 s). Other modules import `SIM` (or build their own
`SimConfig`) instead of hard-coding numbers.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass(frozen=True)
class Timing:
    """Physics, control and observation rates."""

    timestep_s: float = 0.0025
    control_hz: float = 40.0
    observation_hz: float = 2.0
    n_steps: int = 15  # observations per episode, at t = 0, 0.5, ..., 7.0 s
    settle_s: float = 0.5  # the last block after observation 14; success is judged at its end

    @property
    def substeps(self) -> int:
        """Physics steps per control tick (10)."""
        return round(1.0 / (self.control_hz * self.timestep_s))

    @property
    def ticks_per_step(self) -> int:
        """Control ticks per observation step (20)."""
        return round(self.control_hz / self.observation_hz)

    @property
    def duration_s(self) -> float:
        """Episode length: 15 blocks of 0.5 s (7.5 s)."""
        return self.n_steps / self.observation_hz

    def step_time(self, k: int) -> float:
        """Time of observation k."""
        return k / self.observation_hz


@dataclass(frozen=True)
class Noise:
    """Per-seed variation; see sim/README.md for why each number is what it is."""

    cube_xy_m: float = 0.01  # uniform +- on the cube's start position
    cube_yaw_rad: float = np.deg2rad(4.0)  # uniform +- on the cube's start yaw
    start_joint_rad: float = np.deg2rad(1.0)  # Gaussian on the start posture (operator's start)
    waypoint_m: float = 0.003  # Gaussian on each free-space end-effector waypoint (hand tremor)
    force_n: float = 0.05  # Gaussian finger force-sensor noise (per axis)
    torque_nm: float = 0.002  # Gaussian finger torque-sensor noise (per axis)
    finger_m: float = 0.0001  # Gaussian finger-encoder noise


@dataclass(frozen=True)
class Servo:
    """Joint position servos (torque = kp * error - kv * velocity, clipped to Franka's limits).

    Gravity is compensated (as Franka's own controller does), so moderate gains track a 2 Hz
    plan to about a degree and an impact visibly deflects the arm.
    """

    kp: tuple[float, ...] = (1500.0, 1500.0, 1200.0, 1200.0, 300.0, 300.0, 100.0)
    kv: tuple[float, ...] = (150.0, 150.0, 100.0, 100.0, 20.0, 20.0, 8.0)
    gripper_kp: float = 2000.0  # N/m on the finger opening; 70 N cap (Franka Hand continuous)
    gripper_kv: float = 40.0
    gripper_force_n: float = 70.0
    gripper_open_m: float = 0.04  # per-finger opening when open
    gripper_closed_m: float = 0.0  # command when closed (the cube stops the fingers)


@dataclass(frozen=True)
class Seeds:
    """Disjoint seed ranges, so no fault episode ever reuses a demonstration's variation."""

    demos: int = 0
    held_out: int = 10_000
    faults: int = 100_000
    client: int = 50_000  # episodes the streaming client runs: none of the sets above


@dataclass(frozen=True)
class VariedTask:
    """Ranges of the varied task (sim/varied.py): what changes between its episodes.

    Offsets are uniform +- around each skill's nominal layout. Benign out-of-range episodes
    draw every parameter from +- `ood_factor` times its range, at least one of them beyond it.
    """

    n_steps: int = 20  # observations per episode (10 s): room for a 20 % slower execution
    cube_xy_m: float = 0.10
    cube_yaw_deg: float = 45.0
    target_xy_m: float = 0.08
    speed: float = 0.20  # execution speed 1 +- this
    post_offset_m: float = 0.04  # the obstacle's offset across the straight route
    ood_factor: float = 1.3
    perceived_xy_m: float = 0.003  # Gaussian noise of the perceived cube and obstacle positions
    perceived_yaw_deg: float = 2.0
    n_demos: int = 40  # demonstrations per skill


@dataclass(frozen=True)
class SimConfig:
    timing: Timing = field(default_factory=Timing)
    noise: Noise = field(default_factory=Noise)
    servo: Servo = field(default_factory=Servo)
    seeds: Seeds = field(default_factory=Seeds)
    varied: VariedTask = field(default_factory=VariedTask)
    success_tolerance_m: float = 0.01


SIM = SimConfig()
