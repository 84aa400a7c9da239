"""Episodes and episode sets of the varied task (`nasm demos --task varied`).

Sets, on seed ranges of their own (a varied episode's random stream is tagged with the task,
so it never repeats a paper-task episode):

- `demos`: `SIM.varied.n_demos` demonstrations per skill;
- `normal`: held-out in-range episodes (error spreads, conformal calibration, measured false
  alarms);
- `ood`: benign out-of-range episodes: parameters up to 30 % beyond the demonstrated ranges,
  at least one beyond; normal operation that a monitor should not flag;
- `faults`: the fault families of `sim.varied_faults`, over varied contexts;
- `twins`: each fault's seed without the fault;
- `val_faults`, `val_twins`: validation faults and their twins, the same families and skills on
  a quarter of the episodes (`VALIDATION_PLAN`), for choices that need faults (the either-of-two
  rival, experiments/varied/pairs.py) without touching the faults that are measured.

Files are the paper task's format (`sim.dataset`): `<set>.mcap` plus its `.npz` cache, with
the episode's context and the recorded channels (25 + 7 context channels) in every episode.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from neural_asm.sim.config import SIM
from neural_asm.sim.episode import Episode
from neural_asm.sim.task import EpisodeSpec, Prepared, SetSizes
from neural_asm.sim.varied import (VARIED_SKILLS, Context, PerceptionNoise, PlanNoise, draw_perception_noise,
                                   draw_plan_noise, keyframes, make_plan, perceived, post_xy, sample_context,
                                   with_context_channels)
from neural_asm.sim.varied_faults import (FORCE_CHANNELS, PLAN_FAULTS, PlacePost, RestoreFriction, VariedFault,
                                          apply_sensor_fault, execution_effects)

VARIED_KINDS = ("demos", "normal", "ood", "faults", "twins", "val_faults", "val_twins")
SEED_BASE = {"demos": 0, "normal": 10_000, "ood": 20_000, "faults": 100_000, "val_faults": 200_000}
TASK_TAG = 7  # separates the varied task's random streams from the paper task's
HOLDING = ("pick_place_right", "pick_place_around", "lift_hold")
# (kind, episodes, skills it applies to)
FAULT_PLAN: tuple[tuple[str, int, tuple[str, ...]], ...] = (
    ("lock", 240, VARIED_SKILLS), ("small_overshoot", 80, VARIED_SKILLS), ("drift", 80, VARIED_SKILLS),
    ("slip", 48, HOLDING), ("gripper_open", 48, HOLDING), ("force_bias", 48, VARIED_SKILLS),
    ("stray_post", 48, ("pick_place_right", "pick_place_around", "push")), ("wrong_side", 40, ("pick_place_around",)),
    ("wrong_cube", 48, VARIED_SKILLS),
)
# The validation faults: each family on its skills, a quarter of its test count and at least 8.
VALIDATION_PLAN = tuple((kind, max(8, count // 4), skills) for kind, count, skills in FAULT_PLAN)


@dataclass(frozen=True)
class VariedJob:
    skill: str
    seed: int
    fault: VariedFault | None = None
    out_of_range: bool = False


@dataclass(frozen=True)
class VariedVariation:
    """What a varied job's seed draws: the context, then (each from a stream of its own) the
    plan's noise, the sensor noise and the perception's noise."""

    context: Context
    plan: PlanNoise
    sensor: np.ndarray  # (T, 14) standard normal, wrench and finger channels
    perception: PerceptionNoise


def _rng(job: VariedJob, stream: int, draw: int = 0) -> np.random.Generator:
    """Stream 0 draws the context, streams 1-3 the plan, execution and perception noise; a
    draw k > 0 of streams 1-3 is a fresh one of its own."""
    key = (int(job.seed), VARIED_SKILLS.index(job.skill), TASK_TAG, stream)
    return np.random.default_rng(key if stream == 0 or draw == 0 else (*key, draw))


def context_of(job: VariedJob) -> Context:
    return sample_context(job.skill, _rng(job, 0), job.out_of_range)


class _CubeYaw:
    """Records the cube's yaw at every observation instant (the perception system's input)."""

    def __init__(self, n: int) -> None:
        self.yaw = np.zeros(n)

    def initialize(self, physics, scene) -> None:
        self.yaw[:] = 0.0

    def before_tick(self, physics, scene, tick) -> None:
        if tick.index % SIM.timing.ticks_per_step == 0:
            w, _, _, z = physics.bind(scene.cube).qpos[3:7]
            self.yaw[tick.step] = 2.0 * np.arctan2(z, w)


@dataclass(frozen=True)
class VariedTask:
    """The varied task (observed at 2 Hz): its sets, and a job's context, plan and effects."""

    kinds: tuple[str, ...] = VARIED_KINDS

    def jobs(self, kind: str, sizes: SetSizes = SetSizes()) -> list[VariedJob]:
        """The jobs of varied set `kind` (one of VARIED_KINDS)."""
        return jobs_for(kind, sizes)

    def variation(self, job: VariedJob) -> VariedVariation:
        return self.redraw(job, 0)

    def redraw(self, job: VariedJob, draw: int) -> VariedVariation:
        """The job's context with draw `draw` of its noise (0: the seed's own; k > 0: fresh
        tremor, start posture, sensor and perception noise, the same for the same k)."""
        n = SIM.varied.n_steps
        return VariedVariation(context_of(job), draw_plan_noise(_rng(job, 1, draw)),
                               _rng(job, 2, draw).standard_normal((n, 14)),
                               draw_perception_noise(_rng(job, 3, draw), n))

    def prepare(self, job: VariedJob, variation: VariedVariation) -> Prepared:
        """The job's plan in its context (a plan fault replans it), its posts and fault effects;
        its finish applies a sensor fault and adds what perception reports (25 + 7 channels)."""
        ctx, fault = variation.context, job.fault
        wrong_cube = None
        if fault is not None and fault.kind == "wrong_cube":
            wrong_cube = ctx.cube_xy + fault.value * np.asarray(fault.direction)
        plan = make_plan(job.skill, ctx, variation.plan, wrong_side=fault is not None and fault.kind == "wrong_side",
                         cube_xy=wrong_cube)
        tracker = _CubeYaw(len(plan.joints))
        effects = [RestoreFriction(), tracker, PlacePost(0, post_xy(job.skill, ctx)), *execution_effects(fault)]
        if fault is not None and fault.kind == "stray_post":
            effects.append(PlacePost(1, stray_post_xy(job.skill, ctx)))
        target = np.array([*(ctx.cube_xy if job.skill == "lift_hold" else ctx.goal_xy), 0.025])
        spec = EpisodeSpec(job.skill, job.seed, plan.joints, plan.gripper, ctx.cube_xy, ctx.cube_yaw, target,
                           variation.sensor, tuple(effects), fault)

        def finish(episode: Episode) -> Episode:
            episode = replace(episode, observations=apply_sensor_fault(episode.observations, fault), task=ctx.to_dict())
            return with_context_channels(episode, perceived(episode, job.skill, ctx, tracker.yaw, variation.perception))

        return Prepared(spec, finish)


VARIED = VariedTask()


def stray_post_xy(skill: str, ctx: Context) -> np.ndarray:
    """Where an unreported post blocks the skill's path."""
    pos, _, _ = keyframes(skill, ctx)
    if skill == "push":  # halfway along the push, where the cube runs into it
        return ctx.cube_xy + np.array([0.5 * (ctx.goal_xy[0] - ctx.cube_xy[0]) + 0.05, 0.0])
    return pos[7, :2]


def _step_in(ctx: Context, lo: float, hi: float, rng: np.random.Generator) -> int:
    """A random observation step whose phase lies in [lo, hi]."""
    k = np.arange(1, SIM.varied.n_steps)
    choices = k[(k * ctx.speed >= lo) & (k * ctx.speed <= hi)]
    return int(rng.choice(choices))


def draw_fault(kind: str, job: VariedJob, rng: np.random.Generator) -> VariedFault:
    """A fault of `kind` for the job's context (times chosen where the fault can act)."""
    ctx = context_of(job)
    carry = lambda: _step_in(ctx, 6.0, 9.0, rng)  # noqa: E731 - holding the cube, on the way
    joint = int(rng.integers(1, 8))
    if kind == "lock":
        return VariedFault(kind, _step_in(ctx, 1.0, 12.0, rng), joint, float(rng.choice(np.arange(-15, 16, 5))))
    if kind == "small_overshoot":
        return VariedFault(kind, _step_in(ctx, 1.0, 12.0, rng), joint, float(rng.choice([-2.5, 2.5])))
    if kind == "drift":
        return VariedFault(kind, _step_in(ctx, 1.0, 8.0, rng), joint, float(rng.uniform(0.25, 1.0) * rng.choice([-1, 1])))
    if kind == "slip":
        return VariedFault(kind, carry(), 0, float(rng.uniform(2e-4, 1e-3)))
    if kind == "gripper_open":
        return VariedFault(kind, carry())
    if kind == "force_bias":
        channel = int(rng.choice(FORCE_CHANNELS))
        return VariedFault(kind, _step_in(ctx, 1.0, 12.0, rng), channel, float(rng.uniform(0.5, 2.0) * rng.choice([-1, 1])))
    if kind in ("stray_post", "wrong_side"):
        return VariedFault(kind, _step_in(ctx, 6.0, 6.0 + ctx.speed, rng))
    if kind == "wrong_cube":
        angle = rng.uniform(0, 2 * np.pi)
        return VariedFault(kind, 1, 0, float(rng.uniform(0.06, 0.10)), (float(np.cos(angle)), float(np.sin(angle))))
    raise ValueError(f"unknown fault kind {kind!r}")


def fault_jobs(validation: bool = False) -> list[VariedJob]:
    """The test faults (`FAULT_PLAN`) or, with `validation`, the validation faults
    (`VALIDATION_PLAN`, seeds of their own)."""
    plan, base = (VALIDATION_PLAN, SEED_BASE["val_faults"]) if validation else (FAULT_PLAN, SEED_BASE["faults"])
    jobs = []
    for kind, count, skills in plan:
        for i in range(count):
            job = VariedJob(skills[i % len(skills)], base + len(jobs))
            jobs.append(replace(job, fault=draw_fault(kind, job, np.random.default_rng((job.seed, TASK_TAG, 9)))))
    return jobs


def jobs_for(kind: str, sizes: SetSizes = SetSizes()) -> list[VariedJob]:
    """The jobs of varied set `kind` (one of VARIED_KINDS)."""
    n_demos = SIM.varied.n_demos if sizes.n_demos is None else sizes.n_demos
    n_normal = 850 if sizes.n_normal is None else sizes.n_normal
    n_ood = 200 if sizes.n_ood is None else sizes.n_ood
    k = len(VARIED_SKILLS)
    if kind == "demos":
        return [VariedJob(skill, SEED_BASE["demos"] + i) for skill in VARIED_SKILLS for i in range(n_demos)]
    if kind == "normal":
        return [VariedJob(VARIED_SKILLS[i % k], SEED_BASE["normal"] + i) for i in range(n_normal)]
    if kind == "ood":
        return [VariedJob(VARIED_SKILLS[i % k], SEED_BASE["ood"] + i, out_of_range=True) for i in range(n_ood)]
    if kind in ("faults", "val_faults"):
        return fault_jobs(validation=kind == "val_faults")
    if kind in ("twins", "val_twins"):
        return [replace(job, fault=None) for job in fault_jobs(validation=kind == "val_twins")]
    raise ValueError(f"kind must be one of {VARIED_KINDS}, got {kind!r}")


__all__ = ["VARIED", "VARIED_KINDS", "VariedJob", "VariedTask", "VariedVariation", "jobs_for", "PLAN_FAULTS"]
