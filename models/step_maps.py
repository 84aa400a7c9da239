"""Linear maps per skill over step-coded features: what plan recall (models/plan.py) and the
template it is compared with (rivals/templates.py: StepRidgeTemplate) are made of.

A step's one-hot e_t, and its outer product with the episode's context c, give each step its own
linear function of the context; one ridge regression per skill over every step fits them all
with one strength, chosen by generalised cross-validation.
"""

from __future__ import annotations

import numpy as np
from sklearn.linear_model import RidgeCV

RIDGES = np.logspace(-2, 4, 13)


def with_one(a: np.ndarray) -> np.ndarray:
    return np.concatenate([a, np.ones(a.shape[:-1] + (1,))], axis=-1)


def step_codes(t: np.ndarray, steps: int) -> np.ndarray:
    """(..., steps): the one-hot of each step index t among the demonstrations' `steps`, the last
    step's past their end."""
    codes = np.zeros(np.shape(t) + (steps,))
    np.put_along_axis(codes, np.minimum(t, steps - 1)[..., None], 1.0, axis=-1)
    return codes


def input_features(context: np.ndarray, codes: np.ndarray) -> np.ndarray:
    """[e_t, e_t (x) c] of step codes (..., T) and contexts (..., C) that broadcast together:
    (..., T * (C + 1))."""
    outer = codes[..., :, None] * context[..., None, :]
    codes = np.broadcast_to(codes, outer.shape[:-1])
    return np.concatenate([codes, outer.reshape(outer.shape[:-2] + (-1,))], axis=-1)


def ridge_maps(features: np.ndarray, x: np.ndarray, labels: np.ndarray, names: tuple[str, ...]) -> np.ndarray:
    """(K, F + 1, D): per skill, x (N, T, D) ridge-regressed on features (N, T, F), the ridge by
    generalised cross-validation."""
    out = []
    for s in names:
        rows = labels == s
        ridge = RidgeCV(alphas=RIDGES).fit(features[rows].reshape(-1, features.shape[-1]),
                                           x[rows].reshape(-1, x.shape[-1]))
        out.append(np.vstack([ridge.coef_.T, ridge.intercept_[None]]))
    return np.stack(out)


def apply_maps(maps: np.ndarray, features: np.ndarray, skill: np.ndarray) -> np.ndarray:
    """Each row's features (B, ..., F) through its skill's map (K, F + 1, D): one product per skill,
    no copy of the maps per row."""
    out = np.empty(features.shape[:-1] + (maps.shape[2],))
    for k in np.unique(skill):
        rows = skill == k
        out[rows] = with_one(features[rows]) @ maps[k]
    return out
