"""What one step of an episode leaves in a recording, independent of the format."""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class StepRecord:
    """The model's view of one observation step; fields it did not compute stay None."""

    step: int
    observation: np.ndarray  # (D,) original units
    expected: np.ndarray | None = None  # (D,) what the model expected of this step
    prediction: np.ndarray | None = None  # (D,) forecast of the next step
    errors: np.ndarray | None = None  # (D,) precision-weighted prediction errors
    energy: float | None = None
    threshold: float | None = None
    fault: bool | None = None
    isolated_joint: str | None = None
    time_s: float | None = None  # episode time; default step * step period

    @property
    def margin(self) -> float | None:
        """log10(energy / threshold): the threshold at 0 whatever the energies' scale (they
        span 1e1..1e6, which on a linear axis squashes the threshold onto zero)."""
        if self.energy is None or self.threshold is None or self.energy <= 0 or self.threshold <= 0:
            return None
        return math.log10(self.energy / self.threshold)


@dataclass(frozen=True)
class Workcell:
    """The fixed geometry of the scene (m): what the 3D views draw around the arm."""

    table_center: tuple[float, float, float]
    table_half_size: tuple[float, float, float]
    cube_half_size: float
    box_half_size: tuple[float, float, float]  # the falling box


@dataclass(frozen=True)
class WorldRecord:
    """The robot's world at one instant, for the 3D view (all positions in metres).

    ``link_positions[i + 1]`` lies on the axis of the i-th joint channel (the base is row 0),
    which is where the views mark a faulty joint.
    """

    time_s: float
    link_positions: np.ndarray | None = None  # (K, 3) base to hand, drawn as capsules
    link_quaternions: np.ndarray | None = None  # (K, 4) xyzw, frames of those links
    ee: np.ndarray | None = None  # (3,) tool centre point, appended to the path
    cube: np.ndarray | None = None  # (3,) cube centre
    box: np.ndarray | None = None  # (3,) falling box centre, once an episode's box falls
    workcell: Workcell | None = None  # drawn once per file, from the first record carrying it


@dataclass(frozen=True)
class StepBatch:
    """Scored steps of several sessions: row i belongs to the session recorded as ``keys[i]``."""

    keys: list[str]
    steps: list[int]
    observation: np.ndarray  # (B, D), and likewise expected, prediction, errors
    expected: np.ndarray
    prediction: np.ndarray
    errors: np.ndarray
    energy: np.ndarray  # (B,), and likewise threshold, fault
    threshold: np.ndarray
    fault: np.ndarray
    isolated_joint: list[str | None]

    def records(self) -> Iterator[tuple[str, StepRecord]]:
        for i, key in enumerate(self.keys):
            yield key, StepRecord(self.steps[i], self.observation[i], self.expected[i], self.prediction[i],
                                  self.errors[i], float(self.energy[i]), float(self.threshold[i]),
                                  bool(self.fault[i]), self.isolated_joint[i])
