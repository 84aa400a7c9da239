"""Simulated Franka Panda pick-and-place for Neural ASMs (see sim/README.md)."""

import os

# dm_control warns about a missing display on import unless told not to render.
os.environ.setdefault("MUJOCO_GL", "disable")
