"""Entity paths shared by every writer, and the default Rerun layouts over them.

A client and the service log to the same paths of one recording id, so their files
merge into one view; the service logs the model's side (scores, joints), the client
the world (arm, end-effector path, cube).
"""

from __future__ import annotations

from functools import cache

import rerun.blueprint as rrb

WORLD = "/world"
ARM = "/world/arm"
ARM_JOINTS = "/world/arm/joints"
FAULTY_JOINT = "/world/arm/faulty_joint"  # a red sphere on the isolated joint, from the fault's detection
EE_PATH = "/world/ee_path"
CUBE = "/world/cube"
TABLE = "/world/table"
BOX = "/world/falling_box"
ENERGY = "/fault/energy"  # [energy, threshold]
MARGIN = "/fault/margin"  # [log10(energy / threshold), 0]: the threshold at 0 whatever the energies' scale
FLAG = "/fault/flag"
EVENTS = "/events"  # fault detected, isolated joint changed
ERRORS = "/errors"
OBSERVATION = "/observation"
JOINTS_OBSERVED = "/joints/observed"
JOINTS_EXPECTED = "/joints/expected"
TRAIN_ENERGY = "/train/energy"

ENERGY_SERIES = ("energy", "threshold")
MARGIN_SERIES = ("log10(energy / threshold)", "threshold")
SHOWN_ERRORS = 5  # channels drawn in the error view: the largest peaks of the episode
# Looking at the workcell from the front right, above the table: the whole arm, the cube and
# the place targets in view (the Panda's base at the origin, the table ahead along +x).
EYE = rrb.EyeControls3D(position=(1.05, -1.45, 0.95), look_target=(0.3, 0.0, 0.3), eye_up=(0.0, 0.0, 1.0))


# One layout object per process: each view and container draws a random id when built, and
# Rerun interns the entity path parts made of them without ever freeing them (~2.5 KB a file).
@cache
def _episode_views() -> rrb.Container:
    return rrb.Horizontal(
        rrb.Vertical(
            rrb.Spatial3DView(origin=WORLD, name="Panda", eye_controls=EYE),
            rrb.TextLogView(origin=EVENTS, name="Events"),
            row_shares=[4, 1],
        ),
        rrb.Vertical(
            rrb.TimeSeriesView(origin=MARGIN, name="Energy against threshold (log10 energy / threshold; above 0: fault)"),
            rrb.TimeSeriesView(origin=FLAG, name="Fault flag"),
            rrb.TimeSeriesView(origin=ERRORS, name=f"Weighted prediction error, the {SHOWN_ERRORS} largest channels"),
            rrb.TimeSeriesView(origin="/joints", name="Joint angles (rad): observed (lines), expected (crosses)"),
        ),
        column_shares=[2, 3],
    )


@cache
def episode_blueprint() -> rrb.Blueprint:
    return rrb.Blueprint(_episode_views(), rrb.TimePanel(timeline="time"), collapse_panels=True)


def episode_end_blueprint() -> rrb.Blueprint:
    """The episode layout with the time cursor following the data to its end: what a
    screenshot shows (the whole path, every event, the faulty joint marked)."""
    return rrb.Blueprint(_episode_views(), rrb.TimePanel(state="collapsed", timeline="time", play_state="following"),
                         collapse_panels=True)


@cache
def training_blueprint() -> rrb.Blueprint:
    return rrb.Blueprint(rrb.TimeSeriesView(origin=TRAIN_ENERGY, name="Training energy per epoch"))
