"""Sheahan-inspired demonstrations in the Panda's task space (paper, Appendix 2).

Each demonstration is a motor plan: a minimum-jerk reach from S to the central target
T that bows sideways (the plan that would cancel a CW or CCW curl field), then a
follow-through to the skill's secondary target. Channels are the hand position in the
plane, the 7 joint angles from the Panda's inverse kinematics (mink, on the project's
MJCF model, tool pointing down) and a one-hot visual cue of the secondary target.

The hand and joints are the motor channels (the position controller's plan); the cue
is the sensory channel (what the S-to-M baseline sees). The three conditions share the
same hand paths and differ only in what the data shows:
- plan_and_execute: cue from step 0, follow-through executed;
- plan_only: cue from step 0, the hand stays at T instead of following through;
- execute_only: follow-through executed, but the cue is zeros before ``cue_onset``.
"""

from __future__ import annotations

from functools import lru_cache
from typing import Sequence

import numpy as np

from neural_asm.experiments.contextual.config import CONDITIONS, SKILLS, ContextualConfig, Skill
from neural_asm.models.sequences import Sequences

HAND_CHANNELS = ("ee_x", "ee_y")
JOINT_CHANNELS = tuple(f"q{i}" for i in range(1, 8))
MOTOR_CHANNELS = HAND_CHANNELS + JOINT_CHANNELS
# Null-space reference posture of the IK: elbow up, tool down, in front of the base.
HOME_POSTURE = np.array([0.0, -0.3, 0.0, -2.2, 0.0, 1.9, np.pi / 4])


def motor_index(names: Sequence[str]) -> np.ndarray:
    """Indices of the motor channels (hand position and joint angles) among `names`."""
    return np.array([i for i, n in enumerate(names) if n in MOTOR_CHANNELS])


def sensory_index(names: Sequence[str]) -> np.ndarray:
    """Indices of the sensory channels (the visual cue) among `names`."""
    return np.array([i for i, n in enumerate(names) if n not in MOTOR_CHANNELS])


def hand(data: Sequences) -> np.ndarray:
    """(N, T, 2) hand positions of contextual sequences."""
    return data.data[..., [data.channel_names.index(n) for n in HAND_CHANNELS]]


def channel_names(skills: Sequence[Skill]) -> tuple[str, ...]:
    return MOTOR_CHANNELS + tuple(f"cue_{s.name}" for s in skills)


def _min_jerk(u: np.ndarray) -> np.ndarray:
    return u**3 * (10 - 15 * u + 6 * u * u)


def _rotate(vec: np.ndarray, deg: float) -> np.ndarray:
    c, s = np.cos(np.deg2rad(deg)), np.sin(np.deg2rad(deg))
    return np.array([c * vec[0] - s * vec[1], s * vec[0] + c * vec[1]])


def hand_path(skill: Skill, cfg: ContextualConfig, rng: np.random.Generator) -> np.ndarray:
    """One demonstration's hand path (steps, 2): bowed reach to T, then follow-through."""
    start = np.asarray(cfg.start_xy) + cfg.start_jitter_m * rng.standard_normal(2)
    target = np.asarray(cfg.target_xy) + cfg.target_jitter_m * rng.standard_normal(2)
    bow = skill.bow_m * (1 + cfg.bow_jitter * rng.standard_normal())
    axis = np.asarray(cfg.target_xy) - np.asarray(cfg.start_xy)
    axis /= np.linalg.norm(axis)
    left = np.array([-axis[1], axis[0]])
    s = _min_jerk(np.linspace(0, 1, cfg.reach_steps))[:, None]
    reach = start + s * (target - start) + bow * np.sin(np.pi * s) * left
    u = _min_jerk(np.arange(1, cfg.follow_steps + 1) / cfg.follow_steps)[:, None]
    follow = target + u * cfg.follow_m * _rotate(axis, skill.follow_deg)
    return np.concatenate([reach, follow])


@lru_cache(maxsize=1)
def _ik():  # one solver per process: building the MuJoCo model takes ~0.5 s
    from neural_asm.sim.ik import PandaIK

    return PandaIK(tol_m=1e-4, tol_rad=1e-3, max_iters=200)


def joint_angles(path: np.ndarray, cfg: ContextualConfig) -> np.ndarray:
    """Panda joint angles (steps, 7) along a hand path, tool pointing down."""
    from neural_asm.sim.skills import DOWN

    q, out = HOME_POSTURE, []
    for xy in path:
        q = _ik().solve(np.array([xy[0], xy[1], cfg.height_m]), DOWN, q, HOME_POSTURE)
        out.append(q)
    return np.array(out)


def cue(labels: np.ndarray, width: int, condition: str, cfg: ContextualConfig) -> np.ndarray:
    """One-hot visual cue (N, steps, width); zeros before the onset in execute-only."""
    onehot = np.eye(width)[labels][:, None].repeat(cfg.steps, axis=1)
    if condition == "execute_only":
        onehot[:, : cfg.cue_onset] = 0.0
    return onehot


def balanced_labels(n: int, n_skills: int) -> np.ndarray:
    if n % n_skills:
        raise ValueError(f"{n} trials cannot be split evenly over {n_skills} skills")
    return np.repeat(np.arange(n_skills), n // n_skills)


def assemble(
    paths: np.ndarray, joints: np.ndarray, labels: np.ndarray, skills: Sequence[Skill],
    condition: str, cfg: ContextualConfig,
) -> Sequences:
    """The sequences one condition shows, from shared executed paths and joint angles."""
    if condition not in CONDITIONS:
        raise ValueError(f"condition must be one of {CONDITIONS}, got {condition!r}")
    paths, joints = paths.copy(), joints.copy()
    if condition == "plan_only":  # no follow-through: hold at T
        last = cfg.reach_steps - 1
        paths[:, last + 1 :] = paths[:, last : last + 1]
        joints[:, last + 1 :] = joints[:, last : last + 1]
    sequences = np.concatenate([paths, joints, cue(labels, len(skills), condition, cfg)], axis=-1)
    return Sequences(sequences, labels, channel_names(skills), provenance={"condition": condition})


def sample(
    skills: Sequence[Skill], n: int, cfg: ContextualConfig, rng: np.random.Generator
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """n executed trials split evenly over the skills: paths, joint angles, labels."""
    labels = balanced_labels(n, len(skills))
    paths = np.array([hand_path(skills[k], cfg, rng) for k in labels])
    joints = np.array([joint_angles(p, cfg) for p in paths])
    return paths, joints, labels


@lru_cache(maxsize=8)
def conditions_data(
    seed: int, cfg: ContextualConfig, test: bool, n_skills: int = 2, cue_width: int | None = None
) -> dict[str, Sequences]:
    """All three conditions of one participant (seed): training demos or test trials.

    ``cue_width`` pads the cue to a fixed number of skills, so that datasets with
    1..max_skills skills have the same channels (Appendix 3).
    """
    skills = SKILLS[:n_skills]
    rng = np.random.default_rng([seed, int(test), n_skills])
    paths, joints, labels = sample(skills, cfg.test_trials if test else cfg.demos, cfg, rng)
    cue_skills = SKILLS[: cue_width or n_skills]
    return {c: assemble(paths, joints, labels, cue_skills, c, cfg) for c in CONDITIONS}
