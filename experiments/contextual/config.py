"""Every constant of the contextual-inference experiment in one typed place."""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any

from neural_asm.experiments.options import Simulates, option
from neural_asm.models.config import PRESETS

CONDITIONS: tuple[str, ...] = ("plan_and_execute", "plan_only", "execute_only")
MODELS: tuple[str, ...] = ("neural_asm", "s_to_m", "sm_to_sm")
# How reports and figures name the conditions and the models.
LABELS = {
    "plan_and_execute": "plan & execute", "plan_only": "plan only", "execute_only": "execute only",
    "neural_asm": "Neural ASM", "s_to_m": "S-to-M RNN", "sm_to_sm": "SM-to-SM RNN",
    "demonstrations": "demonstrations",
}


@dataclass(frozen=True)
class Skill:
    """One motor plan: a lateral bow on the way to T, then a follow-through direction."""

    name: str
    bow_m: float  # signed peak deviation from the S->T line (+ = left of the movement)
    follow_deg: float  # direction of the secondary target from T, relative to S->T


# CW: a clockwise curl field pushes the hand right of the movement, so the compensating
# plan bows left (+); CCW mirrors it. Each perturbation is tied to one secondary target,
# as the cue-field association in Sheahan et al. The last two only serve the
# "learning speed vs number of skills" result (Appendix 3).
SKILLS: tuple[Skill, ...] = (
    Skill("CW", +0.03, +45.0),
    Skill("CCW", -0.03, -45.0),
    Skill("CW_wide", +0.015, +90.0),
    Skill("CCW_wide", -0.015, -90.0),
)


@dataclass(frozen=True)
class ContextualConfig:
    # Task space: a horizontal plane in front of the Panda (base frame, metres).
    start_xy: tuple[float, float] = (0.30, 0.0)  # S
    target_xy: tuple[float, float] = (0.50, 0.0)  # T, the central target
    height_m: float = 0.30
    follow_m: float = 0.12  # distance from T to a secondary target
    # Time: reach S->T in reach_steps samples (the last one at T), then follow through.
    reach_steps: int = 10
    follow_steps: int = 5
    # Execute-only: the cue appears at this step (mid-reach), zeros before.
    cue_onset: int = 5
    # Trial-to-trial variation of the demonstrations (and of the test trials).
    start_jitter_m: float = 0.005
    bow_jitter: float = 0.1  # relative
    target_jitter_m: float = 0.003
    # Protocol (paper: 6 participants, 1200 exposure trials, 24 post-exposure trials).
    seeds: int = 6
    demos: int = 24  # training demonstrations, split evenly over the skills
    test_trials: int = 24  # recall trials, split evenly over the skills
    epochs: int = 1200
    inference_sweep: tuple[int, ...] = (1, 2, 5, 10, 20, 50, 100, 200)
    max_skills: int = 4  # energy vs number of skills for 1..max_skills
    skill_seeds: int = 3  # participants in that side result (each run costs a full training)

    @property
    def steps(self) -> int:
        return self.reach_steps + self.follow_steps

    def with_(self, **changes: Any) -> "ContextualConfig":
        return replace(self, **changes)


CONTEXTUAL = ContextualConfig()
# The tPC preset `nasm contextual` uses unless told otherwise: FAST trained on noisy observations.
# FAST without noise recalls the plan from an exactly relaxed cue (Gauss-Newton) 10-25x worse
# than the RNNs on some seeds: the exact minimum of the cue's energy fits that trial's jitter,
# a hidden state the noise-free training never visited, and the W_H roll-out amplifies it;
# truncated gradient descent stops short of it, which is why recall error was lowest at
# K = 20-50 and rose again towards the exact value as K grew. Noise in training makes the
# roll-out return from such states. `faithful` stays the paper's setting.
DEFAULT_PRESET = "robust"
# A reduced protocol for tests and --quick: one seed, few epochs, a short sweep.
QUICK = CONTEXTUAL.with_(seeds=1, skill_seeds=1, epochs=300, inference_sweep=(1, 5, 20, 100))


@dataclass(frozen=True)
class ContextualRun(Simulates):
    """Neural ASM vs S-to-M and SM-to-SM RNNs on plan & execute / plan only / execute only: PEAD
    (panels E, F), recall error vs inference iterations (G), energy vs number of skills
    (Appendix 3) and the dataset (Appendix 2)."""

    seeds: int | None = option(None, "participants (seeds); default 6, 1 with --quick", min=1)
    epochs: int | None = option(None, "learning epochs of every model; default 1200, 300 with --quick", min=1)
    preset: str = option(DEFAULT_PRESET, f"tPC hyper-parameters, shared by the RNNs (but for the training "
                         f"noise): {', '.join(PRESETS)}")
    quick: bool = option(False, "reduced protocol: 1 seed, 300 epochs, short K sweep")

    def __post_init__(self) -> None:
        if self.preset not in PRESETS:
            raise ValueError(f"preset must be one of {', '.join(PRESETS)}, got {self.preset!r}")

    @property
    def protocol(self) -> ContextualConfig:
        """The protocol this run follows: QUICK or CONTEXTUAL with the seeds and epochs given."""
        cfg = QUICK if self.quick else CONTEXTUAL
        cfg = cfg.with_(**{k: v for k, v in (("seeds", self.seeds), ("epochs", self.epochs)) if v is not None})
        return cfg.with_(skill_seeds=min(cfg.skill_seeds, cfg.seeds))
