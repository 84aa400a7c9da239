"""The executor every task shares: reset the workcell to an `EpisodeSpec`'s scene, track its
2 Hz joint plan at 40 Hz, observe at 2 Hz (the paper's skill layer) or at 40 Hz (every control
tick); and running a task's jobs (`simulate`, `run_job`, `run_jobs`).

The loop per 40 Hz tick is: the controller interpolates the plan linearly between observation
steps (target plus velocity feed-forward); an optional correction hook may replace the target;
then every effect (fault, disturbance) acts; then 10 physics steps of 2.5 ms. The joint
controller (`SimConfig.controller`: stiff servos or compliant impedance, both gravity
compensated) acts at every physics step, as a robot's 1 kHz torque loop does under its slower
set-point stream. MuJoCo warnings or a diverging state raise `SimulationError`: an unstable
episode is never returned as data.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from typing import Callable

import mujoco
import numpy as np
from dm_control import mjcf

from neural_asm.sim.channels import EE_CHANNELS, FINGER_CHANNELS, GRIPPER_CHANNEL, JOINT_CHANNELS, N_CHANNELS, WRENCH_CHANNELS
from neural_asm.sim.config import SIM, ControllerKind
from neural_asm.runtime.parallel import Backend, Parallel
from neural_asm.sim.effects import Tick
from neural_asm.sim.episode import Episode
from neural_asm.sim.ik import IKError
from neural_asm.sim.panda import Q_MAX, Q_MIN
from neural_asm.sim.scene import BOX_PARK, CUBE_HALF, SceneHandles, build_scene
from neural_asm.sim.skills import PlanError
from neural_asm.sim.task import EpisodeSpec, J, Task, V

_CHANNELS = np.arange(N_CHANNELS)
N_JOINTS, N_EE = len(_CHANNELS[JOINT_CHANNELS]), len(_CHANNELS[EE_CHANNELS])
N_WRENCH, N_FINGER = len(_CHANNELS[WRENCH_CHANNELS]), len(_CHANNELS[FINGER_CHANNELS])
N_NOISY = N_WRENCH + N_FINGER  # the wrench and finger channels get sensor noise, drawn in this order


class SimulationError(RuntimeError):
    """MuJoCo reported a warning or the state diverged; the episode's data is not trustworthy."""


@dataclass
class ControlState:
    """What a correction hook sees at each 40 Hz tick."""

    tick: int
    time_s: float
    step: int  # observation block k (the tick moves from t_k towards t_k+1)
    q: np.ndarray  # (7,) measured joint angles
    qd: np.ndarray  # (7,) measured joint velocities
    ee: np.ndarray  # (3,) tool centre point
    target: np.ndarray  # (7,) the plan's target for the end of this tick
    torque: np.ndarray  # (7,) joint torques the controller applied at the last physics step (N m)
    observations: np.ndarray  # (n, 25) observations so far (a new one arrives when the tick starts an observation period)
    # (7,) external joint torques at the last physics step (N m): what contacts (a box on the arm,
    # the carried cube) exert at each joint, which a torque-sensing arm such as the Panda estimates
    external_torque: np.ndarray
    stiffness: np.ndarray  # (7,) the joint controller's stiffness (N m/rad): set-point offset -> torque


CorrectionHook = Callable[[ControlState], "np.ndarray | None"]


@dataclass
class World:
    """The compiled workcell and, resolved once through `physics.bind`, where its state lives."""

    physics: mjcf.Physics
    scene: SceneHandles
    arm_qpos: np.ndarray  # qpos addresses of joints 1..7
    arm_dof: np.ndarray
    finger_qpos: np.ndarray
    arm_act: np.ndarray
    grip_act: int
    tcp_site: int
    cube_body: int
    box_body: int
    wrench_adr: np.ndarray  # sensordata addresses in channel order (left f, left t, right f, right t)
    box_defaults: tuple[float, np.ndarray, float]  # falling box mass, inertia, gravcomp (disturbances change them)

    @property
    def qpos(self) -> np.ndarray:
        return self.physics.data.qpos[self.arm_qpos]


@lru_cache(maxsize=None)
def world() -> World:
    """One compiled workcell per process (compiling costs far more than resetting)."""
    scene = build_scene(SIM.timing.timestep_s)
    physics = mjcf.Physics.from_mjcf_model(scene.root)
    p = scene.panda
    sensors = [s for pair in zip(p.force_sensors, p.torque_sensors) for s in pair]
    wrench = np.concatenate([physics.bind(s).adr + np.arange(3) for s in sensors])
    return World(physics, scene, physics.bind(p.joints).qposadr.copy(), physics.bind(p.joints).dofadr.copy(),
                 physics.bind(p.finger_joints).qposadr.copy(), physics.bind(p.actuators).element_id.copy(),
                 int(physics.bind(p.gripper).element_id), int(physics.bind(p.tcp).element_id),
                 int(physics.bind(scene.cube_body).element_id), int(physics.bind(scene.box_body).element_id),
                 wrench, (float(physics.bind(scene.box_body).mass), physics.bind(scene.box_body).inertia.copy(),
                         float(physics.bind(scene.box_body).gravcomp)))


def set_joint_gains(w: World, controller: ControllerKind) -> tuple[np.ndarray, np.ndarray]:
    """Give the arm's joint actuators `controller`'s stiffness and damping; return the stiffness
    and damping / stiffness.

    The actuators are MuJoCo position actuators, torque = K (ctrl - q) - D qd, so one actuator
    serves both controllers: only its gains change (no recompilation). The returned ratio turns
    a velocity feed-forward into the ctrl offset that yields K (q* - q) + D (qd* - qd).
    """
    stiffness, damping = SIM.joint_gains(controller)
    model = w.physics.model
    model.actuator_gainprm[w.arm_act, 0] = stiffness
    model.actuator_biasprm[w.arm_act, 1] = -stiffness
    model.actuator_biasprm[w.arm_act, 2] = -damping
    return stiffness, damping / stiffness


def _reset(w: World, plan0: np.ndarray, cube_xy: np.ndarray, cube_yaw: float) -> np.ndarray:
    """Put the arm at the plan's start, the cube on the table; return the sensors' tare."""
    physics, scene = w.physics, w.scene
    physics.reset()
    box = physics.bind(scene.box_body)
    box.mass, box.inertia, box.gravcomp = w.box_defaults
    physics.bind(scene.panda.joints).qpos = plan0
    physics.bind(scene.panda.finger_joints).qpos = SIM.servo.gripper_open_m
    physics.bind(scene.cube).qpos = [*cube_xy, CUBE_HALF, np.cos(cube_yaw / 2), 0, 0, np.sin(cube_yaw / 2)]
    physics.bind(scene.box).qpos = [*BOX_PARK, 1, 0, 0, 0]
    physics.bind(scene.panda.actuators).ctrl = plan0
    physics.bind(scene.panda.gripper).ctrl = SIM.servo.gripper_open_m
    physics.forward()
    return physics.data.sensordata[w.wrench_adr].copy()


def _check(physics: mjcf.Physics, counts: np.ndarray) -> None:
    if counts.any():
        names = [mujoco.mjtWarning(i).name for i in np.flatnonzero(counts)]
        raise SimulationError(f"MuJoCo warnings at t={physics.data.time:.3f}s: {names}")


def _observe(w: World, gripper: float, tare: np.ndarray, noise: np.ndarray) -> np.ndarray:
    physics = w.physics
    data = physics.data
    mujoco.mj_forward(physics.model.ptr, data.ptr)
    scale = np.tile(np.r_[[SIM.noise.force_n] * 3, [SIM.noise.torque_nm] * 3], N_WRENCH // 6)
    obs = np.empty(N_CHANNELS)
    obs[JOINT_CHANNELS] = w.qpos
    obs[EE_CHANNELS] = data.site_xpos[w.tcp_site]
    obs[FINGER_CHANNELS] = data.qpos[w.finger_qpos] + noise[N_WRENCH:] * SIM.noise.finger_m
    obs[GRIPPER_CHANNEL] = gripper
    obs[WRENCH_CHANNELS] = data.sensordata[w.wrench_adr] - tare + noise[:N_WRENCH] * scale
    return obs


def execute(spec: EpisodeSpec, hook: CorrectionHook | None = None) -> Episode:
    """Execute `spec`'s joint plan (T, 7) and gripper toggles (T,), given at the skill layer's
    2 Hz, observed at `spec.rate` (2 or 40 Hz; `spec.noise` holds one row per observation).

    The low-level loop every task shares: T blocks of 20 control ticks each. `hook`, if given,
    is called before every tick with a `ControlState` and may return a (7,) joint target
    replacing the plan's (None keeps it); the spec's effects act after it.
    """
    timing, w = SIM.timing, world()
    physics, scene = w.physics, w.scene
    model, data = physics.model.ptr, physics.data.ptr
    joints, gripper, noise = spec.joints, spec.gripper, spec.noise
    stiffness, kv_over_kp = set_joint_gains(w, SIM.controller if spec.controller is None else spec.controller)
    tare = _reset(w, joints[0], spec.cube_xy, spec.cube_yaw)
    for effect in spec.effects:
        effect.initialize(physics, scene)
    warnings = physics.data.warning.number  # a live view of MuJoCo's warning counters
    block, n = timing.ticks_per_step, len(joints)
    period = timing.ticks_per_observation(spec.rate)
    hi = {key: np.empty((n * block + 1, width)) for key, width in
          (("q", N_JOINTS), ("cmd", N_JOINTS), ("ee", N_EE), ("cube", 3), ("box", 3))}

    def record(row: int, command: np.ndarray) -> None:
        hi["q"][row] = data.qpos[w.arm_qpos]
        hi["cmd"][row] = command
        hi["ee"][row] = data.site_xpos[w.tcp_site]
        hi["cube"][row] = data.xpos[w.cube_body]
        hi["box"][row] = data.xpos[w.box_body]

    record(0, joints[0])
    obs = []
    for index in range(n * block):
        k, sub = divmod(index, block)
        if index % period == 0:
            obs.append(_observe(w, gripper[k], tare, noise[len(obs)]))
        nxt = joints[min(k + 1, n - 1)]
        tick = Tick(index, index / timing.control_hz, k, joints, joints[k] + (sub + 1) / block * (nxt - joints[k]),
                    (nxt - joints[k]) * timing.observation_hz, bool(gripper[k]))
        if hook is not None:
            state = ControlState(index, tick.time_s, k, w.qpos, data.qvel[w.arm_dof].copy(),
                                 data.site_xpos[w.tcp_site].copy(), tick.target.copy(),
                                 data.actuator_force[w.arm_act].copy(), np.array(obs),
                                 data.qfrc_constraint[w.arm_dof].copy(), stiffness)
            corrected = hook(state)
            if corrected is not None:
                tick.target = np.asarray(corrected, dtype=float).reshape(N_JOINTS)
        for effect in spec.effects:
            effect.before_tick(physics, scene, tick)
        target = np.minimum(np.maximum(tick.target, Q_MIN), Q_MAX)
        data.ctrl[w.arm_act] = target + kv_over_kp * tick.velocity
        data.ctrl[w.grip_act] = SIM.servo.gripper_closed_m if tick.gripper_closed else SIM.servo.gripper_open_m
        mujoco.mj_step(model, data, timing.substeps)
        _check(physics, warnings)
        record(index + 1, target)
    observations = np.array(obs)
    if not np.isfinite(observations).all():
        raise SimulationError("non-finite observation")
    cube_error = float(np.linalg.norm(hi["cube"][-1] - spec.cube_goal))
    return Episode(observations=observations, skill=spec.skill, seed=int(spec.seed), fault=spec.fault,
                   disturbance=spec.disturbance, success=cube_error < SIM.success_tolerance_m, cube_error_m=cube_error,
                   plan=joints.copy(), rate_hz=float(spec.rate),
                   t_hi=np.arange(n * block + 1) / timing.control_hz, qpos_hi=hi["q"],
                   command_hi=hi["cmd"], ee_hi=hi["ee"], cube_hi=hi["cube"], box_hi=hi["box"])


def simulate(task: Task[J, V], job: J, variation: V | None = None) -> Episode:
    """`task`'s episode of `job`, under the variation its seed draws or the `variation` given."""
    prepared = task.prepare(job, task.variation(job) if variation is None else variation)
    return prepared.finish(execute(prepared.spec))


def run_job(task: Task[J, V], job: J, variation: V | None = None) -> Episode | str:
    """`simulate`, with a failed episode coming back as its error message (never as data)."""
    try:
        return simulate(task, job, variation)
    except (SimulationError, PlanError, IKError) as err:
        return f"{job.skill} seed {job.seed}: {err}"  # type: ignore[attr-defined]


def run_jobs(task: Task[J, V], jobs: list[J], workers: int = 2, desc: str = "episodes",
             backend: Backend = "processes") -> tuple[list[Episode], list[str]]:
    """Run `task`'s jobs over `workers` processes or on Ray (in order), with a progress bar;
    the episodes, and the failures' messages."""
    results = Parallel(workers, backend).map(run_job, [(task, job) for job in jobs], desc=desc, unit="ep",
                                                                   chunksize=8)
    return [r for r in results if isinstance(r, Episode)], [r for r in results if isinstance(r, str)]
