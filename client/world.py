"""The arm, tool, cube and falling box at 40 Hz for the recordings' 3D view, from a simulated episode."""

from __future__ import annotations

import numpy as np

from neural_asm.recordings.records import Workcell, WorldRecord
from neural_asm.sim.episode import Episode
from neural_asm.sim.panda import dh_frames
from neural_asm.sim.scene import BOX_HALF, CUBE_HALF, TABLE_CENTER, TABLE_HALF

WORKCELL = Workcell(table_center=TABLE_CENTER, table_half_size=TABLE_HALF, cube_half_size=CUBE_HALF,
                    box_half_size=BOX_HALF)


def link_positions(q: np.ndarray) -> np.ndarray:
    """(10, 3) origins of the base, the 8 DH frames (Franka's table) and the tool centre point;
    row i (1..7) lies on joint i's axis."""
    return np.array([frame[:3, 3] for frame in dh_frames(q)])


def world_trace(ep: Episode) -> tuple[WorldRecord, ...]:
    """Every 40 Hz world row of the episode; the falling box after its release (the row at the
    release instant still has it parked, out of sight)."""
    release_s = None if ep.disturbance is None else ep.disturbance.release_s
    rows = []
    for row, t in enumerate(map(float, ep.t_hi)):
        falling = release_s is not None and t > release_s + 1e-9
        rows.append(WorldRecord(time_s=t, link_positions=link_positions(ep.qpos_hi[row]), ee=ep.ee_hi[row],
                                cube=ep.cube_hi[row], box=ep.box_hi[row] if falling else None, workcell=WORKCELL))
    return tuple(rows)
