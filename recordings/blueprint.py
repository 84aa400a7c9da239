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
EE_PATH = "/world/ee_path"
CUBE = "/world/cube"
ENERGY = "/fault/energy"  # [energy, threshold]
FLAG = "/fault/flag"
ERRORS = "/errors"
OBSERVATION = "/observation"
JOINTS_OBSERVED = "/joints/observed"
JOINTS_EXPECTED = "/joints/expected"
TRAIN_ENERGY = "/train/energy"

ENERGY_SERIES = ("energy", "threshold")


# One layout object per process: each view and container draws a random id when built, and
# Rerun interns the entity path parts made of them without ever freeing them (~2.5 KB a file).
@cache
def episode_blueprint() -> rrb.Blueprint:
    return rrb.Blueprint(
        rrb.Horizontal(
            rrb.Spatial3DView(origin=WORLD, name="Panda"),
            rrb.Vertical(
                rrb.TimeSeriesView(origin=ENERGY, name="Energy and threshold"),
                rrb.TimeSeriesView(origin=FLAG, name="Fault flag"),
                rrb.TimeSeriesView(origin=ERRORS, name="Weighted prediction error per channel"),
                rrb.TimeSeriesView(origin="/joints", name="Joint angles: observed vs expected (rad)"),
            ),
            column_shares=[2, 3],
        ),
        collapse_panels=True,
    )


@cache
def training_blueprint() -> rrb.Blueprint:
    return rrb.Blueprint(rrb.TimeSeriesView(origin=TRAIN_ENERGY, name="Training energy per epoch"))
