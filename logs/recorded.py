"""One episode as a reader hands it over: values on the model's clock, a skill name, its origin."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Recorded:
    data: np.ndarray  # (steps, D), the mapping's channels in order, in the mapping's units
    label: str  # skill name: from a label topic or task, else the bag's or dataset's name
    origin: str  # where it was read, for messages and provenance
    start_s: float  # its first sample, on the source's clock
    number: int  # its number in the source (bags: in reading order; LeRobot: episode_index)
