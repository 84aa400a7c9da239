"""The arm, tool and cube at 40 Hz for the recordings' 3D view, from a simulated episode."""

from __future__ import annotations

from typing import Iterator

import numpy as np

from recordings.records import WorldRecord
from sim.episode import Episode
from sim.panda import dh_frames


def link_positions(q: np.ndarray) -> np.ndarray:
    """(10, 3) origins of the base, the 8 DH frames (Franka's table) and the tool centre point."""
    return np.array([frame[:3, 3] for frame in dh_frames(q)])


def world_records(ep: Episode, upto_s: float, start_row: int) -> Iterator[tuple[int, WorldRecord]]:
    """40 Hz world rows from ``start_row`` with time <= ``upto_s``."""
    row = start_row
    while row < len(ep.t_hi) and ep.t_hi[row] <= upto_s + 1e-9:
        yield row, WorldRecord(time_s=float(ep.t_hi[row]), link_positions=link_positions(ep.qpos_hi[row]),
                               ee=ep.ee_hi[row], cube=ep.cube_hi[row])
        row += 1
