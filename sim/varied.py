"""The varied task: four skills whose every episode differs, as real skills do.

Per episode the cube's start pose (+-10 cm, yaw +-45 deg), the goal (+-8 cm) and the execution
speed (+-20 %) are drawn (`sim.config.VariedTask`). One skill carries the cube around a post
standing between cube and goal: where the post stands across the straight route decides
whether the arm passes left or right of it, a context-to-trajectory map with two modes that no
smooth template follows. Skills:

- `pick_place_right`: pick the cube on the left, place it at a goal on the right;
- `pick_place_around`: pick on the right, carry it around the post to a goal on the left;
- `lift_hold`: pick the cube, hold it up at a goal point, put it back where it was;
- `push`: fingers closed, push the cube along x to a goal line.

A skill is a list of keyframes (tool-centre-point position, hand yaw, gripper) over a phase
0..14. Execution speed s maps observation step k to phase min(s k, 14); each step's pose is
interpolated between keyframes and solved by IK (null space pulled to the skill's nominal
posture at that phase). Observations are the 25 channels of the paper's task plus what a
perception system reports: the cube's pose (noisy, every step), the goal and the post's
position. `hidden` context drops the goal: the monitor must infer it from the motion.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from functools import lru_cache

import numpy as np

from neural_asm.sim.channels import (CHANNEL_NAMES, EE_CHANNELS, FINGER_CHANNELS, GRIPPER_CHANNEL, JOINT_NAMES,
                          WRENCH_CHANNELS)
from neural_asm.sim.config import SIM
from neural_asm.sim.episode import Episode
from neural_asm.sim.scene import CUBE_HALF, POST_PARK
from neural_asm.sim.skills import DOWN, check_velocity, shared_ik

VARIED_SKILLS: tuple[str, ...] = ("pick_place_right", "pick_place_around", "lift_hold", "push")
CONTEXT_NAMES: tuple[str, ...] = ("cube_seen_x", "cube_seen_y", "cube_seen_yaw", "goal_x", "goal_y", "post_x", "post_y")
HIDDEN_CONTEXT: tuple[str, ...] = ("goal_x", "goal_y")
CONTEXTS = ("observed", "hidden")
LAST_PHASE = 14
CARRY, HOVER, HOLD_Z = 0.15, 0.15, 0.30
DETOUR_M = 0.24  # how far from the post the carry passes (the hand and wrist must clear it)


def check_context(context: str) -> str:
    """The context variant's name, refused unless it is one of `CONTEXTS`."""
    if context not in CONTEXTS:
        raise ValueError(f"context must be one of {CONTEXTS}, got {context!r}")
    return context


def channel_names(context: str) -> tuple[str, ...]:
    """The observation channels of a context variant."""
    check_context(context)
    extra = CONTEXT_NAMES if context == "observed" else tuple(n for n in CONTEXT_NAMES if n not in HIDDEN_CONTEXT)
    return (*CHANNEL_NAMES, *extra)


@dataclass(frozen=True)
class Layout:
    """A skill's nominal cube and goal positions and its start pose."""

    cube_xy: tuple[float, float]
    goal_xy: tuple[float, float]
    start_tcp: tuple[float, float, float]
    home: tuple[float, ...]  # reference posture of the IK's null space at the start


LAYOUTS = {
    "pick_place_right": Layout((0.45, 0.25), (0.45, -0.25), (0.30, 0.30, 0.45), (0.3, -0.3, 0.0, -2.4, 0.0, 2.1, 0.785)),
    "pick_place_around": Layout((0.55, -0.25), (0.55, 0.25), (0.50, -0.35, 0.30), (-0.3, 0.0, 0.0, -2.2, 0.0, 2.2, 0.785)),
    "lift_hold": Layout((0.52, -0.05), (0.45, 0.05), (0.35, -0.15, 0.45), (0.0, 0.0, 0.0, -2.2, 0.0, 2.2, 0.785)),
    "push": Layout((0.42, 0.05), (0.57, 0.05), (0.30, 0.05, 0.30), (0.2, 0.2, 0.0, -2.3, 0.0, 2.5, 0.785)),
}


@dataclass(frozen=True)
class Context:
    """What one episode's world looks like: drawn per seed, reported (partly) to the monitor."""

    cube_xy: np.ndarray  # (2,) m
    cube_yaw: float  # rad
    goal_xy: np.ndarray  # (2,) m
    speed: float
    post_offset: float  # m across the route (pick_place_around), 0 otherwise
    out_of_range: bool = False

    def to_dict(self) -> dict:
        return {"cube_xy": [float(v) for v in self.cube_xy], "cube_yaw": float(self.cube_yaw),
                "goal_xy": [float(v) for v in self.goal_xy], "speed": float(self.speed),
                "post_offset": float(self.post_offset), "out_of_range": bool(self.out_of_range)}

    @classmethod
    def from_dict(cls, d: dict) -> "Context":
        return cls(np.asarray(d["cube_xy"]), float(d["cube_yaw"]), np.asarray(d["goal_xy"]), float(d["speed"]),
                   float(d["post_offset"]), bool(d["out_of_range"]))


def sample_context(skill: str, rng: np.random.Generator, out_of_range: bool = False) -> Context:
    """Draw a context: inside the demonstrated ranges, or (benign OOD) up to 30 % beyond them."""
    cfg, layout = SIM.varied, layout_of(skill)
    half = np.array([cfg.cube_xy_m, cfg.cube_xy_m, np.deg2rad(cfg.cube_yaw_deg), cfg.target_xy_m, cfg.target_xy_m,
                     cfg.speed, cfg.post_offset_m])
    scale = cfg.ood_factor if out_of_range else 1.0
    u = rng.uniform(-scale, scale, len(half))
    if skill != "pick_place_around":
        u[6] = 0.0
    if skill == "push":
        u[4] = 0.0  # the goal line is along the cube's own y
    while out_of_range and not (np.abs(u) > 1.0).any():
        u = rng.uniform(-scale, scale, len(half))
        if skill != "pick_place_around":
            u[6] = 0.0
        if skill == "push":
            u[4] = 0.0
    v = u * half
    cube = np.asarray(layout.cube_xy) + v[:2]
    goal = np.asarray(layout.goal_xy) + v[3:5]
    if skill == "push":
        goal[1] = cube[1]
    return Context(cube, float(v[2]), goal, 1.0 + float(v[5]), float(v[6]), out_of_range)


def layout_of(skill: str) -> Layout:
    if skill not in LAYOUTS:
        raise ValueError(f"skill must be one of {VARIED_SKILLS}, got {skill!r}")
    return LAYOUTS[skill]


def post_xy(skill: str, ctx: Context) -> np.ndarray:
    """Where the post stands: the route's midpoint, shifted across it (parked when unused)."""
    if skill != "pick_place_around":
        return np.asarray(POST_PARK[0][:2])
    across = _across(ctx.cube_xy, ctx.goal_xy)
    return 0.5 * (ctx.cube_xy + ctx.goal_xy) + ctx.post_offset * across


def _across(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    d = (b - a) / np.linalg.norm(b - a)
    return np.array([d[1], -d[0]])


def keyframes(skill: str, ctx: Context, wrong_side: bool = False, cube_xy: np.ndarray | None = None
              ) -> tuple[np.ndarray, np.ndarray, tuple[float, float]]:
    """(15, 3) positions and (15,) hand yaws at phases 0..14, and the phases the gripper is
    closed in [close, open). `wrong_side` routes around the post on the wrong side, `cube_xy`
    plans for a cube where it is not (both are faults)."""
    layout = layout_of(skill)
    cube = ctx.cube_xy if cube_xy is None else cube_xy
    up = np.array([0.0, 0.0, 1.0])
    start = np.asarray(layout.start_tcp)
    grasp = np.array([*cube, CUBE_HALF])
    goal = np.array([*ctx.goal_xy, CUBE_HALF + 0.002])
    yaw = ctx.cube_yaw
    if skill == "push":
        behind = np.array([cube[0] - 0.045, cube[1], 0.03])
        end = np.array([ctx.goal_xy[0] - 0.045, ctx.goal_xy[1], 0.03])
        push = [behind + f * (end - behind) for f in np.linspace(0.0, 1.0, 8)]
        pos = [start, behind + [-0.04, 0, HOVER], behind + [-0.04, 0, 0], *push, end, end + HOVER * up,
               end + [-0.05, 0, HOVER + 0.1], end + [-0.05, 0, HOVER + 0.1]]
        return np.array(pos), np.zeros(15), (0.0, LAST_PHASE + 1.0)
    if skill == "lift_hold":
        hold = np.array([*ctx.goal_xy, HOLD_Z])
        pos = [start, grasp + HOVER * up, grasp + 0.05 * up, grasp, grasp, grasp, grasp + HOVER * up, hold, hold,
               grasp + HOVER * up, grasp + 0.002 * up, grasp + 0.002 * up, grasp + 0.002 * up, grasp + 0.10 * up,
               grasp + HOVER * up]
        yaws = np.r_[0.0, [yaw] * 14]
        return np.array(pos), yaws, (3.5, 10.5)
    if skill == "pick_place_around":
        post = np.array([*post_xy(skill, ctx), 0.0])
        side = -np.sign(ctx.post_offset) or 1.0
        if wrong_side:
            side = -side
        across = np.array([*_across(ctx.cube_xy, ctx.goal_xy), 0.0])
        middle = post + side * DETOUR_M * across + CARRY * up
    else:
        middle = 0.5 * (grasp + goal) + (CARRY + 0.05) * up
    pos = [start, grasp + HOVER * up, grasp + 0.05 * up, grasp, grasp, grasp, grasp + CARRY * up, middle,
           goal + HOVER * up, goal + 0.05 * up, goal, goal, goal, goal + 0.10 * up, goal + HOVER * up]
    yaws = np.r_[0.0, [yaw] * 14]
    return np.array(pos), yaws, (3.5, 10.5)


def _rotation(yaw: float) -> np.ndarray:
    c, s = np.cos(yaw), np.sin(yaw)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]) @ DOWN


def _interpolate(values: np.ndarray, phase: float) -> np.ndarray:
    i = min(int(np.floor(phase)), LAST_PHASE - 1)
    f = phase - i
    return (1 - f) * values[i] + f * values[i + 1]


@lru_cache(maxsize=None)
def nominal_postures(skill: str) -> np.ndarray:
    """(15, 7) joint angles at the keyframes of the skill's nominal context: the null-space
    reference that keeps every episode's redundant joints where the skill usually has them."""
    layout = layout_of(skill)
    ctx = Context(np.asarray(layout.cube_xy), 0.0, np.asarray(layout.goal_xy), 1.0, 0.02)
    pos, yaws, _ = keyframes(skill, ctx)
    home = np.asarray(layout.home)
    q = [shared_ik().solve(pos[0], _rotation(yaws[0]), home, home)]
    for k in range(1, len(pos)):
        q.append(shared_ik().solve(pos[k], _rotation(yaws[k]), q[-1], home))
    out = np.array(q)
    out.flags.writeable = False
    return out


@dataclass(frozen=True)
class VariedPlan:
    joints: np.ndarray  # (T, 7)
    gripper: np.ndarray  # (T,) 0/1
    tcp: np.ndarray  # (T, 3)
    phases: np.ndarray  # (T,)


@dataclass(frozen=True)
class PlanNoise:
    tremor: np.ndarray  # (T, 3) m, on the free-space waypoints
    start: np.ndarray  # (7,) rad, the operator's start posture


def draw_plan_noise(rng: np.random.Generator) -> PlanNoise:
    n = SIM.varied.n_steps
    return PlanNoise(rng.normal(0.0, SIM.noise.waypoint_m, (n, 3)), rng.normal(0.0, SIM.noise.start_joint_rad, 7))


def make_plan(skill: str, ctx: Context, noise: PlanNoise, wrong_side: bool = False,
              cube_xy: np.ndarray | None = None) -> VariedPlan:
    """The episode's 2 Hz plan: keyframes time-warped by the speed, tremor, IK."""
    n = SIM.varied.n_steps
    pos, yaws, (close, release) = keyframes(skill, ctx, wrong_side, cube_xy)
    phases = np.minimum(np.arange(n) * ctx.speed, LAST_PHASE)
    nominal = nominal_postures(skill)
    tremor, start_noise = noise.tremor, noise.start
    tcp = np.array([_interpolate(pos, p) for p in phases])
    free = (phases > 1.0) & (phases < 2.0) | (phases > 6.0) & (phases < 8.0)  # free-space moves only
    tcp[free] += tremor[free]
    q = [nominal[0] + start_noise]
    for k in range(1, n):
        yaw = float(_interpolate(yaws[:, None], phases[k])[0])
        q.append(shared_ik().solve(tcp[k], _rotation(yaw), q[-1], _interpolate(nominal, phases[k])))
    joints = np.array(q)
    check_velocity(joints, margin=1.0)  # the limit itself: a 20 % faster detour runs close to it
    gripper = ((phases >= close) & (phases < release)).astype(float)
    return VariedPlan(joints, gripper, tcp, phases)


@dataclass(frozen=True)
class PerceptionNoise:
    """What the perception system gets wrong at each step (m, rad)."""

    cube_xy: np.ndarray  # (T, 2)
    cube_yaw: np.ndarray  # (T,)
    post_xy: np.ndarray  # (T, 2)


def draw_perception_noise(rng: np.random.Generator, n: int) -> PerceptionNoise:
    cfg = SIM.varied
    cube = rng.normal(0.0, cfg.perceived_xy_m, (n, 2))
    yaw = rng.normal(0.0, np.deg2rad(cfg.perceived_yaw_deg), n)
    return PerceptionNoise(cube, yaw, rng.normal(0.0, cfg.perceived_xy_m, (n, 2)))


def perceived(episode: Episode, skill: str, ctx: Context, cube_yaw: np.ndarray, noise: PerceptionNoise) -> np.ndarray:
    """(T, 7) context channels (CONTEXT_NAMES): the cube pose a perception system reports at
    each step, the goal and the post."""
    n = len(episode.observations)
    block = SIM.timing.ticks_per_step
    cube = episode.cube_hi[::block][:n, :2] + noise.cube_xy[:n]
    # yaw is tracked continuously from the first sighting (the cube is symmetric under 90 deg)
    turn = (cube_yaw - ctx.cube_yaw + np.pi / 4) % (np.pi / 2) - np.pi / 4
    yaw = ctx.cube_yaw + turn + noise.cube_yaw[:n]
    post = post_xy(skill, ctx) + noise.post_xy[:n]
    columns = {"cube_seen_x": cube[:, 0], "cube_seen_y": cube[:, 1], "cube_seen_yaw": yaw,
               "goal_x": np.full(n, ctx.goal_xy[0]), "goal_y": np.full(n, ctx.goal_xy[1]),
               "post_x": post[:, 0], "post_y": post[:, 1]}
    return np.stack([columns[name] for name in CONTEXT_NAMES], axis=1)


def with_context_channels(episode: Episode, extra: np.ndarray) -> Episode:
    """The episode as the observed variant records it (25 + 7 channels)."""
    return replace(episode, observations=np.concatenate([episode.observations, extra], axis=1),
                   channel_names=(*CHANNEL_NAMES, *CONTEXT_NAMES))


def channel_groups(names: tuple[str, ...]) -> dict[str, list[int]]:
    """The indices of each kind of channel among ``names`` (kinds absent from them are left out)."""
    kinds = {"joints": JOINT_NAMES, "end effector": CHANNEL_NAMES[EE_CHANNELS], "fingers": CHANNEL_NAMES[FINGER_CHANNELS],
             "gripper": (CHANNEL_NAMES[GRIPPER_CHANNEL],), "finger forces and torques": CHANNEL_NAMES[WRENCH_CHANNELS],
             "perceived context": CONTEXT_NAMES}
    groups = {kind: [i for i, n in enumerate(names) if n in members] for kind, members in kinds.items()}
    return {kind: cols for kind, cols in groups.items() if cols}


def context_columns(channel_names_: tuple[str, ...], context: str) -> np.ndarray:
    """Indices of a context variant's channels within the recorded (observed) channels."""
    wanted = channel_names(context)
    return np.array([channel_names_.index(name) for name in wanted])
