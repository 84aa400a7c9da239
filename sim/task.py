"""The one interface every task of the simulator offers, and the episode specification the
executor runs.

A task (the paper's two skills, `sim.paper`; the varied task, `sim.varied_sets`) names its
episode sets and the jobs in them; for a job it draws the variation its seed makes (scene,
start posture, tremor, sensor noise) and, from a job and a variation, prepares an
`EpisodeSpec`: the plan, the scene and the effects (faults, disturbances) the executor
(`sim.runner.execute`) runs, with what turns the raw execution into the task's episode. An
experiment that needs an episode under another variation (the same context with fresh noise,
another speed) draws the variation, changes it (`dataclasses.replace`) and prepares the job
with it: the job itself stays what the product runs.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Callable, Protocol, TypeVar

import numpy as np

from neural_asm.sim.config import SIM, ControllerKind
from neural_asm.sim.disturbances import FallingObject
from neural_asm.sim.effects import Effect
from neural_asm.sim.episode import Episode
from neural_asm.sim.faults import FaultSpec

if TYPE_CHECKING:
    from neural_asm.sim.varied_faults import VariedFault


@dataclass(frozen=True)
class EpisodeSpec:
    """Everything one execution needs: a 2 Hz plan, the scene it starts in, the sensor noise,
    what acts on it, and how it is controlled and observed."""

    skill: str
    seed: int
    joints: np.ndarray  # (T, 7) joint plan at the skill layer's 2 Hz (rad)
    gripper: np.ndarray  # (T,) gripper toggles, 0 open / 1 closed
    cube_xy: np.ndarray  # (2,) the cube's start position (m)
    cube_yaw: float  # rad
    cube_goal: np.ndarray  # (3,) where the cube should end up: success within SIM.success_tolerance_m
    noise: np.ndarray  # (observations, 14) standard normal sensor noise, one row per observation
    effects: tuple[Effect, ...] = ()  # called before every control tick, in this order
    fault: "FaultSpec | VariedFault | None" = None  # recorded in the episode (its effect is among `effects`)
    disturbance: FallingObject | None = None  # recorded in the episode (its effect is among `effects`)
    controller: ControllerKind | None = None  # None: SIM.controller
    rate: float = SIM.timing.observation_hz  # observations per second (sim.config.RATES)


def as_executed(episode: Episode) -> Episode:
    """The episode as the executor returned it (a task that records nothing more)."""
    return episode


@dataclass(frozen=True)
class Prepared:
    """A job made ready to run: its specification, and what the task adds to the executed
    episode (sensor faults, perceived context)."""

    spec: EpisodeSpec
    finish: Callable[[Episode], Episode] = as_executed


@dataclass(frozen=True)
class SetSizes:
    """How many episodes the sizeable sets hold; None: the task's own default."""

    n_demos: int | None = None  # demonstrations per skill
    n_normal: int | None = None  # held-out normal episodes
    n_ood: int | None = None  # benign out-of-range episodes (varied task)


J = TypeVar("J")
V = TypeVar("V")


class Task(Protocol[J, V]):
    """A family of episodes: its sets, their jobs, and for a job its variation and its plan,
    scene and effects."""

    kinds: tuple[str, ...]

    def jobs(self, kind: str, sizes: SetSizes = SetSizes()) -> list[J]:
        """The jobs of set `kind` (one of `kinds`)."""

    def variation(self, job: J) -> V:
        """What the job's seed draws before the episode runs."""

    def prepare(self, job: J, variation: V) -> Prepared:
        """The job's episode under `variation`: plan, scene, effects, and its finish."""
