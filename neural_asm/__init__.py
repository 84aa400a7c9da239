"""Neural ASM: Neural Associative Skill Memories.

A temporal predictive coding network learns a robot's skills from demonstrations with local
Hebbian rules, recognises which skill is running, predicts the rest and flags faults by its
prediction-error energy.
"""

from neural_asm import runtime as _runtime  # noqa: F401  (first: one BLAS thread, no display)
from neural_asm.runtime.version import __version__

__all__ = ["__version__"]
