"""Every constant of the simulation in one typed place.

Timing follows the paper's "Robot simulation details": a 40 Hz position controller under a
2 Hz skill layer, 15 observations (7.5 s). Other modules import `SIM` (or build their own
`SimConfig`) instead of hard-coding numbers.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal, get_args

import numpy as np

ControllerKind = Literal["stiff", "compliant"]
CONTROLLERS: tuple[str, ...] = get_args(ControllerKind)
# Rates an episode can be observed at (Hz): the skill layer's 2 Hz (the paper's) and the
# controller's 40 Hz (every tick). The `--rate` of every command line is one of these.
RATES: tuple[int, ...] = (2, 40)


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

    def ticks_per_observation(self, rate_hz: float) -> int:
        """Control ticks between observations at `rate_hz` (20 at 2 Hz, 1 at 40 Hz), or a
        ValueError naming the rates an episode can be observed at."""
        if rate_hz not in RATES:
            raise ValueError(f"rate must be one of {', '.join(map(str, RATES))} Hz, got {rate_hz!r}")
        return round(self.control_hz / rate_hz)

    def observations(self, rate_hz: float) -> int:
        """Observations per episode at `rate_hz`: 15 at 2 Hz, 300 at 40 Hz (one per tick)."""
        return self.n_steps * self.ticks_per_step // self.ticks_per_observation(rate_hz)


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
class Impedance:
    """Compliant joint impedance: torque = K (q* - q) + D (qd* - qd), gravity compensated.

    The stiffness and damping are the joint impedance Franka ships as its example for
    interacting with people (libfranka's `joint_impedance_control` and franka_ros's
    `joint_impedance_example_controller`: K = 600 Nm/rad on the four big joints down to 50 on
    the wrist). That is 2-2.5x softer than `Servo` on the big joints: a hit pushes the arm
    away instead of being absorbed by a stiff servo, which is the point of compliant control
    near people, and loads the gravity compensation does not know about (a box resting on the
    arm, the carried cube) leave a standing error of load / K.
    """

    stiffness: tuple[float, ...] = (600.0, 600.0, 600.0, 600.0, 250.0, 150.0, 50.0)  # Nm/rad
    damping: tuple[float, ...] = (50.0, 50.0, 50.0, 50.0, 30.0, 25.0, 15.0)  # Nm s/rad


# How long the correction waits for the flags to keep coming, per observation rate (Hz), each
# chosen on the correction experiment's selection seeds as the shortest time that lowered
# recovery by no more than 5 points anywhere, in any of five trainings (docs/rate.md). At 2 Hz,
# 0.5 s: two flagged observations in a row (1.0 s, three in a row, loses the 40 kg m/s gains).
# At 40 Hz, 1.0 s: with each tick's mean error taken out the monitor flags from the blow's own
# tick, and 0.5 s engaged while a 40 kg box was still on the arm (-10 points at 80 kg m/s).
CONFIRM_S: dict[float, float] = {2.0: 0.5, 40.0: 1.0}


@dataclass(frozen=True)
class CorrectionGains:
    """The memory's reactive correction (sim/control.py): q* = q_rec + K_i I, I the leaky
    integral of q_rec - q, its torque bounded by the external torque the arm feels. Chosen on
    selection seeds, never on an experiment's test seeds (experiments/correction)."""

    ki: float = 4.0  # 1/s
    leak: float = 0.25  # 1/s
    i_max_deg: float = 10.0  # bound on K_i I per joint
    # A joint at `yield_torque` of its torque limit for `yield_s` is holding a load the arm
    # should not hold (or pushing a person): the correction lets go for the rest of the episode,
    # and does not engage if the arm got there first. None: never.
    yield_torque: float = 0.9  # fraction of the joint's torque limit
    yield_s: float | None = 0.1
    # How long the flags must keep coming (each within that time of the last) before the
    # correction engages: one flag may be a false alarm, or a blow that is already over (a 40 kg
    # box that slides off the forearm by itself, which a correction engaged at once keeps on the
    # arm into the place). None: the observation rate's own (`CONFIRM_S`), else one time for
    # every rate.
    confirm_s: float | None = None
    # Letting go, the offset decays with this time constant: a set-point step under a heavy
    # load would slam the hand down (at 80 kg m/s it drags the cube 5-7 mm through the fingers).
    release_s: float = 0.05

    def __post_init__(self) -> None:
        if not (self.ki > 0 and self.leak >= 0 and self.i_max_deg > 0):
            raise ValueError(f"correction gains need ki > 0, leak >= 0, i_max_deg > 0, got {self}")
        if not 0 < self.yield_torque <= 1:
            raise ValueError(f"yield_torque must be in (0, 1], got {self.yield_torque}")
        if self.yield_s is not None and not self.yield_s > 0:
            raise ValueError(f"yield_s must be > 0 or None, got {self.yield_s}")
        if self.confirm_s is not None and not self.confirm_s >= 0:
            raise ValueError(f"confirm_s must be >= 0 or None, got {self.confirm_s!r}")
        if not self.release_s > 0:
            raise ValueError(f"release_s must be > 0, got {self.release_s}")

    def confirm_at(self, rate_hz: float) -> float:
        """How long flags must keep coming at observation rate `rate_hz` (s)."""
        if self.confirm_s is not None:
            return self.confirm_s
        if rate_hz not in CONFIRM_S:
            raise ValueError(f"no confirmation time chosen for {rate_hz:g} Hz; have {sorted(CONFIRM_S)} Hz "
                             "(or give confirm_s)")
        return CONFIRM_S[rate_hz]


@dataclass(frozen=True)
class ElbowHit:
    """The falling-object hit (`sim.disturbances.elbow_hit`): a box dropped from `drop_height_m`
    above the elbow (link 4) at `speed_m_s` during the carry (the cube is in the hand from 2.5 s
    to 6.0 s), its mass setting the momentum (mass x speed)."""

    speed_m_s: float = 2.0
    release_s: float = 4.0
    drop_height_m: float = 0.05
    # The client demo's hit (`nasm client --falling-object`): the compliant arm alone drops the
    # cube on one skill there, and the correction places it.
    demo_momentum: float = 40.0
    # The falling-object set of the fault sweep (`sim.paper`): these momenta (kg m/s), each on
    # `set_seeds` seeds, skills alternating.
    set_momenta: tuple[float, ...] = (20.0, 30.0, 40.0, 50.0, 60.0, 70.0, 80.0)
    set_seeds: int = 14


@dataclass(frozen=True)
class Seeds:
    """Disjoint seed ranges, so no fault episode ever reuses a demonstration's variation."""

    demos: int = 0
    held_out: int = 10_000
    faults: int = 100_000
    hits: int = 150_000  # the falling-object set (`sim.paper`): hits and their twins
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
    impedance: Impedance = field(default_factory=Impedance)
    # Which joint controller tracks the plan: the stiff position servos (`servo`, the default
    # every data set was generated with) or the compliant joint impedance (`impedance`).
    controller: ControllerKind = "stiff"
    correction: CorrectionGains = field(default_factory=CorrectionGains)
    hit: ElbowHit = field(default_factory=ElbowHit)
    seeds: Seeds = field(default_factory=Seeds)
    varied: VariedTask = field(default_factory=VariedTask)
    success_tolerance_m: float = 0.01

    def __post_init__(self) -> None:
        _check_controller(self.controller)

    def joint_gains(self, controller: ControllerKind | None = None) -> tuple[np.ndarray, np.ndarray]:
        """(stiffness, damping) per joint of `controller` (default: this config's)."""
        kind = _check_controller(self.controller if controller is None else controller)
        if kind == "stiff":
            return np.asarray(self.servo.kp, float), np.asarray(self.servo.kv, float)
        return np.asarray(self.impedance.stiffness, float), np.asarray(self.impedance.damping, float)


def _check_controller(kind: str) -> str:
    if kind not in CONTROLLERS:
        raise ValueError(f"controller must be one of {CONTROLLERS}, got {kind!r}")
    return kind


SIM = SimConfig()
