"""Energy and prediction errors, for whole sequences and for one streamed step.

The energy of a step is the observation-layer term of eq. 5 evaluated at the
observation: sum_i (e_i / s_ti)^2, with e the normalised prediction error and s_ti the
expected spread of channel i's error at step t (its precision is 1 / s_ti^2). Without
a calibration every s is 1 and the energy is the paper's plain sum of squared errors.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


def step_rows(table: np.ndarray, steps: int) -> np.ndarray:
    """Rows 0..steps-1 of a per-step table, repeating its last row past its end."""
    return table[np.minimum(np.arange(steps), len(table) - 1)]


def energy(errors: np.ndarray, error_std: np.ndarray | None = None) -> np.ndarray:
    """Energy per step of normalised errors (..., T, D); error_std is (T', D) or None."""
    if error_std is None:
        return (errors.astype(np.float64) ** 2).sum(-1)
    std = step_rows(error_std, errors.shape[-2])
    return ((errors / std) ** 2).sum(-1)


@dataclass(frozen=True)
class SequenceScore:
    expected: np.ndarray  # (N, T, D) what the model expected, original units
    errors: np.ndarray  # (N, T, D) observation minus expectation, normalised units
    energy: np.ndarray  # (N, T)


@dataclass(frozen=True)
class StepScore:
    step: int
    expected: np.ndarray  # (D,) what the model expected of this step, original units
    errors: np.ndarray  # (D,) normalised prediction errors
    weighted_errors: np.ndarray  # (D,) errors divided by their expected spread; energy = sum of squares
    energy: float
    prediction: np.ndarray  # (D,) forecast of the next step, original units
