"""Energy and prediction errors, for whole sequences and for one streamed step.

The energy of a step is the observation-layer term of eq. 5 evaluated at the
observation: w^T P_t w with w_i = e_i / s_ti, e the normalised prediction error, s_ti the
expected spread of channel i's error at step t and P_t the precision matrix of w at that
step (the identity when channels are taken as independent: sum_i w_i^2). Without a
calibration every s is 1, P is the identity, and the energy is the paper's plain sum of
squared errors.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


def step_row(table: np.ndarray, step: int) -> np.ndarray:
    """Row `step` of a per-step table, its last row past its end."""
    return table[min(step, len(table) - 1)]


def step_rows(table: np.ndarray, steps: int) -> np.ndarray:
    """Rows 0..steps-1 of a per-step table, repeating its last row past its end."""
    return table[np.minimum(np.arange(steps), len(table) - 1)]


def energy(
    errors: np.ndarray, error_std: np.ndarray | None = None, error_precision: np.ndarray | None = None
) -> np.ndarray:
    """Energy per step of normalised errors (..., T, D); error_std is (T', D) or None,
    error_precision (T', D, D) or None (independent channels)."""
    weighted = errors.astype(np.float64)
    if error_std is not None:
        weighted = weighted / step_rows(error_std, errors.shape[-2])
    return quadratic(weighted, None if error_precision is None else step_rows(error_precision, errors.shape[-2]))


def quadratic(weighted: np.ndarray, precision: np.ndarray | None) -> np.ndarray:
    """w^T P w over the last axis of w (..., D), P (..., D, D) broadcast; sum of squares if P is None."""
    if precision is None:
        return (weighted**2).sum(-1)
    # (w P) . w by matmul: einsum's parsing of its subscripts cost more than a step's arithmetic.
    return ((weighted[..., None, :] @ precision)[..., 0, :] * weighted).sum(-1)


@dataclass(frozen=True)
class SequenceScore:
    """Every step of every scored sequence: what the memory expected, the errors and the energy."""

    expected: np.ndarray  # (N, T, D) what the model expected, original units
    errors: np.ndarray  # (N, T, D) observation minus expectation, normalised units
    energy: np.ndarray  # (N, T)


@dataclass(frozen=True)
class StepScore:
    step: int
    expected: np.ndarray  # (D,) what the model expected of this step, original units
    errors: np.ndarray  # (D,) normalised prediction errors
    weighted_errors: np.ndarray  # (D,) errors divided by their expected spread (what isolation ranks)
    energy: float
    prediction: np.ndarray  # (D,) forecast of the next step, original units
    skill: str | None = None  # the skill recognised at this step (`SkillStream.recognised`)
