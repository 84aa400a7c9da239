"""The paper's task: two pick-and-place skills, its joint-lock faults and the falling object,
its episode sets, and its episodes run or replanned.

Sets (seed ranges from `sim.config.Seeds`, disjoint so no fault or held-out episode reuses a
demonstration's variation):

- `demos`: 10 demonstrations per skill, seeds 0..9;
- `normal`: held-out normal episodes for threshold calibration, seeds 10000..;
- `faults`: the paper's 980 joint-lock faults, each with its own seed 100000 + i;
- `twins`: the same 980 seeds without a fault, so what a fault changes can be measured exactly;
- `hits`: the falling object on the elbow during the carry (`SIM.hit.set_momenta`, 20-80 kg m/s,
  each on `SIM.hit.set_seeds` seeds from 150000), and `hit_twins`, the same seeds without it.

Every set can be observed at 2 Hz (the paper's skill layer) or at 40 Hz (every control tick):
`PaperTask(rate)`. At 40 Hz the observation at every 20th tick is the 2 Hz one, bit for bit
(same physics, same sensor noise), so a 40 Hz episode is its 2 Hz twin plus the 19 ticks
between each pair of observations; the noise of those ticks comes from a stream of its own.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from neural_asm.sim.config import SIM, ControllerKind
from neural_asm.sim.disturbances import FallingObject, elbow_hit, make_effect
from neural_asm.sim.episode import Episode
from neural_asm.sim.faults import FaultSpec, JointLock, fault_grid
from neural_asm.sim.runner import N_JOINTS, N_NOISY, CorrectionHook, execute, simulate
from neural_asm.sim.skills import SKILLS, Variation, make_plan, sample_variation, skill_spec, target_position
from neural_asm.sim.task import EpisodeSpec, Prepared, SetSizes

KINDS = ("demos", "normal", "faults", "twins", "hits", "hit_twins")


@dataclass(frozen=True)
class Job:
    """One episode of the paper's task."""

    skill: str
    seed: int
    fault: FaultSpec | None = None
    disturbance: FallingObject | None = None
    rate: float = SIM.timing.observation_hz  # observations per second (sim.config.RATES)
    controller: ControllerKind | None = None  # None: SIM.controller


@dataclass(frozen=True)
class PaperVariation:
    """What a seed draws: the scene (cube pose, start posture, tremor) and the sensor noise."""

    scene: Variation
    noise: np.ndarray  # (observations, 14) standard normal


def demonstrations(n_per_skill: int = 10) -> list[Job]:
    return [Job(skill, SIM.seeds.demos + i) for skill in SKILLS for i in range(n_per_skill)]


def held_out_normal(n: int = 200) -> list[Job]:
    return [Job(SKILLS[i % len(SKILLS)], SIM.seeds.held_out + i) for i in range(n)]


def faults() -> list[Job]:
    return [Job(skill, SIM.seeds.faults + i, spec) for i, (skill, spec) in enumerate(fault_grid())]


def twins() -> list[Job]:
    return [Job(job.skill, job.seed) for job in faults()]


def hits() -> list[Job]:
    """The falling object on the elbow at each of `SIM.hit.set_momenta`, skills alternating over seeds."""
    momenta, n = SIM.hit.set_momenta, SIM.hit.set_seeds
    return [Job(SKILLS[i % len(SKILLS)], SIM.seeds.hits + i, disturbance=elbow_hit(momenta[i // n]))
            for i in range(len(momenta) * n)]


def hit_twins() -> list[Job]:
    return [Job(job.skill, job.seed) for job in hits()]


def _rng(skill: str, seed: int) -> np.random.Generator:
    return np.random.default_rng((int(seed), SKILLS.index(skill)))


def seed_variation(skill: str, seed: int) -> Variation:
    """What `seed` changes in `skill`'s scene (cube pose, start posture, tremor): what a
    perception of the workcell would report before the episode starts."""
    skill_spec(skill)
    return sample_variation(skill, _rng(skill, seed))


@dataclass(frozen=True)
class PaperTask:
    """The paper's task observed at `rate` (2 or 40 Hz)."""

    rate: float = SIM.timing.observation_hz
    kinds: tuple[str, ...] = KINDS

    def __post_init__(self) -> None:
        SIM.timing.ticks_per_observation(self.rate)  # a ValueError for a rate episodes cannot be observed at

    def jobs(self, kind: str, sizes: SetSizes = SetSizes()) -> list[Job]:
        """The jobs of set `kind` (one of KINDS), observed at the task's rate."""
        table = {"demos": lambda: demonstrations(10 if sizes.n_demos is None else sizes.n_demos),
                 "normal": lambda: held_out_normal(200 if sizes.n_normal is None else sizes.n_normal),
                 "faults": faults, "twins": twins, "hits": hits, "hit_twins": hit_twins}
        if kind not in table:
            raise ValueError(f"kind must be one of {KINDS}, got {kind!r}")
        return [replace(job, rate=self.rate) for job in table[kind]()]

    def variation(self, job: Job) -> PaperVariation:
        """The job's scene variation and sensor noise at its rate: the variation and the 2 Hz
        observations' noise drawn in this order from one stream, the other ticks' noise (at
        40 Hz) from a second stream of the same seed."""
        skill_spec(job.skill)
        rng = _rng(job.skill, job.seed)
        scene = sample_variation(job.skill, rng)
        noise = rng.standard_normal((SIM.timing.n_steps, N_NOISY))
        period = SIM.timing.ticks_per_observation(job.rate)
        if period == SIM.timing.ticks_per_step:
            return PaperVariation(scene, noise)
        ticks = np.random.default_rng((int(job.seed), SKILLS.index(job.skill), period)).standard_normal(
            (SIM.timing.observations(job.rate), N_NOISY))
        ticks[:: SIM.timing.ticks_per_step // period] = noise
        return PaperVariation(scene, ticks)

    def prepare(self, job: Job, variation: PaperVariation) -> Prepared:
        """The demonstrator's IK plan for the job's scene."""
        plan = make_plan(job.skill, variation.scene)
        return Prepared(spec_of(job, variation, plan.joints, plan.gripper))


PAPER = PaperTask()


def spec_of(job: Job, variation: PaperVariation, joints: np.ndarray, gripper: np.ndarray) -> EpisodeSpec:
    """The job's episode executing the 2 Hz plan (`joints`, `gripper`) in its scene."""
    effects = ([] if job.fault is None else [JointLock(job.fault)]) + make_effect(job.disturbance)
    return EpisodeSpec(job.skill, job.seed, joints, gripper, variation.scene.cube_xy, variation.scene.cube_yaw,
                       target_position(job.skill), variation.noise, tuple(effects), job.fault, job.disturbance,
                       job.controller, job.rate)


def run_episode(skill: str, seed: int, fault: FaultSpec | None = None,
                disturbance: FallingObject | None = None, controller: ControllerKind | None = None,
                rate: float = SIM.timing.observation_hz) -> Episode:
    """Plan `skill` for `seed` by IK and execute it, optionally with a fault and/or a disturbance,
    under `controller` (default `SIM.controller`), observed at `rate` (2 or 40 Hz)."""
    return simulate(PAPER, Job(skill, seed, fault, disturbance, rate, controller))


def first_observation(skill: str, seed: int) -> np.ndarray:
    """(25,) the observation `run_episode(skill, seed)` starts with, taken before any motion:
    the cue a memory recalls the skill from, simulating one step of the plan instead of fifteen."""
    job = Job(skill, seed)
    spec = PAPER.prepare(job, PAPER.variation(job)).spec
    return execute(replace(spec, joints=spec.joints[:1], gripper=spec.gripper[:1])).observations[0]


def execute_plan(joint_plan: np.ndarray, gripper_plan: np.ndarray, job: Job,
                 correction_hook: CorrectionHook | None = None) -> Episode:
    """Execute a (15, 7) joint plan (rad) and (15,) gripper toggles given at 2 Hz (e.g. one
    recalled by a model) as `job`'s episode: its scene, sensor noise, fault, disturbance,
    controller and rate, so a recalled plan can be compared with the demonstration of the same
    seed.

    `correction_hook`, if given, is called before every 40 Hz tick with a `ControlState` and
    may return a (7,) joint target replacing the plan's for that tick (None keeps it; at 40 Hz
    its observations gain one every tick); faults and disturbances still act after it. Targets
    are clipped to the joint limits.
    """
    skill_spec(job.skill)
    joints = np.asarray(joint_plan, dtype=float)
    gripper = np.asarray(gripper_plan, dtype=float)
    n = SIM.timing.n_steps
    if joints.shape != (n, N_JOINTS) or not np.isfinite(joints).all():
        raise ValueError(f"joint_plan must be a finite ({n}, {N_JOINTS}) array, got shape {joints.shape}")
    if gripper.shape != (n,) or not np.isin(gripper, (0.0, 1.0)).all():
        raise ValueError(f"gripper_plan must be a ({n},) array of 0/1, got {gripper!r}")
    return execute(spec_of(job, PAPER.variation(job), joints, gripper), correction_hook)
