"""Simulated Franka Panda pick-and-place for Neural ASMs (see sim/README.md)."""

import neural_asm.runtime  # noqa: F401  (dm_control warns about a missing display on import unless told not to render)
