"""What one step of an episode leaves in a recording, independent of the format."""

from __future__ import annotations

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


@dataclass(frozen=True)
class WorldRecord:
    """The robot's world at one instant, for the 3D view (all positions in metres)."""

    time_s: float
    link_positions: np.ndarray | None = None  # (K, 3) base to hand, drawn as capsules
    link_quaternions: np.ndarray | None = None  # (K, 4) xyzw, frames of those links
    ee: np.ndarray | None = None  # (3,) tool centre point, appended to the path
    cube: np.ndarray | None = None  # (3,) cube centre

