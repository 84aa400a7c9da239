"""One episode as a reader hands it over: values on the model's clock, a skill name, its origin
(and, from tables, its anomaly label and onset)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Recorded:
    data: np.ndarray  # (steps, D), the mapping's channels in order, in the mapping's units
    label: str  # skill name: from a label topic or task, else the bag's or dataset's name
    origin: str  # where it was read, for messages and provenance
    start_s: float  # its first sample, on the source's clock
    number: int  # its number in the source (bags, tables: in reading order; LeRobot: episode_index)
    anomaly: str | None = None  # its anomaly label (tables); None: normal
    onset_s: float | None = None  # the anomaly's onset, s after start_s (tables)
    length_s: float | None = None  # its own duration, before any padding (tables)
