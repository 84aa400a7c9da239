"""Ridge one-step regression over past steps: the departure pathway of plan recall (models/plan.py)
and, in `neural_asm.rivals`, the linear one-step rivals.

- ``RidgeOneStep``: x[t+1] ridge-regressed on [x[t], 1].
- ``fit_one_step``: per skill or pooled models on delay-embedded sequences ([x[t], ..., x[t-L+1]]),
  the ridge strength, how many past steps L they read and the pooling chosen by 5-fold
  cross-validation over whole demonstrations (one step knows where the arm is, two also how fast
  it moves: on the varied task two steps halve the held-out joint error).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from sklearn.model_selection import StratifiedKFold

ONE_STEP_RIDGES = (1e-3, 1e-2, 1e-1, 1.0, 10.0, 100.0, 1000.0)
ONE_STEP_LAGS = (1, 2, 3)
POOLINGS = (False, True)  # one model for every skill, or one per skill


@dataclass(frozen=True)
class RidgeOneStep:
    weights: np.ndarray  # (D + 1, D): x[t+1] = [x[t], 1] @ weights

    @classmethod
    def fit(cls, sequences: np.ndarray, ridge: float = 1e-2) -> "RidgeOneStep":
        x = sequences[:, :-1].reshape(-1, sequences.shape[-1])
        y = sequences[:, 1:].reshape(-1, sequences.shape[-1])
        a = np.hstack([x, np.ones((len(x), 1))])
        reg = ridge * np.eye(a.shape[1])
        reg[-1, -1] = 0.0  # do not shrink the bias
        return cls(np.linalg.solve(a.T @ a + reg, a.T @ y))

    def step(self, x: np.ndarray) -> np.ndarray:
        return np.concatenate([x, np.ones(x.shape[:-1] + (1,))], axis=-1) @ self.weights

    def rollout(self, cue: np.ndarray, horizon: int) -> np.ndarray:
        """Offline roll-out from the last cue observation (N, T_n, D) -> (N, horizon, D)."""
        out = list(np.moveaxis(cue, 1, 0))
        while len(out) < horizon:
            out.append(self.step(out[-1]))
        return np.stack(out, axis=1)


def episode_folds(skills: np.ndarray, seed: int, n_folds: int = 5) -> list[tuple[np.ndarray, np.ndarray]]:
    """Train/test indices of whole episodes, every skill in every fold."""
    smallest = np.unique(skills, return_counts=True)[1].min()
    folds = StratifiedKFold(min(n_folds, smallest), shuffle=True, random_state=seed)
    return list(folds.split(np.zeros(len(skills)), skills))


def delay_embed(x: np.ndarray, lags: int) -> np.ndarray:
    """(N, T, D) -> (N, T, lags * D): each step followed by the lags - 1 steps before it, the
    first step standing in for the steps before the start (the embedding stays causal)."""
    parts = [x] + [np.concatenate([np.repeat(x[:, :1], j, axis=1), x[:, :-j]], axis=1) for j in range(1, lags)]
    return np.concatenate(parts, axis=2)


@dataclass(frozen=True)
class OneStep:
    """Ridge one-step models per skill over `lags` past steps."""

    models: dict[str, RidgeOneStep]
    lags: int

    def predict(self, x: np.ndarray, skills: np.ndarray) -> np.ndarray:
        """(N, T-1, D) predictions of steps 1..T-1, each from the steps before it."""
        return _next_step_predictions(self.models, delay_embed(x, self.lags), skills)[..., : x.shape[2]]


def _fit_models(x: np.ndarray, skills: np.ndarray, ridge: float, per_skill: bool) -> dict[str, RidgeOneStep]:
    names = np.unique(skills)
    if per_skill:
        return {s: RidgeOneStep.fit(x[skills == s], ridge) for s in names}
    pooled = RidgeOneStep.fit(x, ridge)
    return {s: pooled for s in names}


def _next_step_predictions(models: dict[str, RidgeOneStep], x: np.ndarray, skills: np.ndarray) -> np.ndarray:
    """(N, T-1, D) predictions of steps 1..T-1, each from the step before."""
    out = np.empty((len(x), x.shape[1] - 1, x.shape[2]))
    for s in np.unique(skills):
        rows = skills == s
        out[rows] = models[s].step(x[rows, :-1])
    return out


def fit_one_step(x: np.ndarray, skills: np.ndarray, seed: int, lag_choices: tuple[int, ...] = ONE_STEP_LAGS,
                 ridges: tuple[float, ...] = ONE_STEP_RIDGES, poolings: tuple[bool, ...] = POOLINGS) -> OneStep:
    """Per-skill one-step models; past steps, ridge and pooling chosen by held-out one-step error
    (no cross-validation where there is one choice)."""
    choices = [(lags, ridge, per_skill) for lags in lag_choices for per_skill in poolings for ridge in ridges]
    if len(choices) > 1:
        choices = [min(choices, key=lambda choice: _held_out_error(x, skills, seed, *choice))]
    lags, ridge, per_skill = choices[0]
    return OneStep(_fit_models(delay_embed(x, lags), skills, ridge, per_skill), lags)


def _held_out_error(x: np.ndarray, skills: np.ndarray, seed: int, lags: int, ridge: float, per_skill: bool) -> float:
    embedded, error = delay_embed(x, lags), 0.0
    for train, test in episode_folds(skills, seed):
        models = _fit_models(embedded[train], skills[train], ridge, per_skill)
        predicted = _next_step_predictions(models, embedded[test], skills[test])[..., : x.shape[2]]
        error += ((predicted - x[test, 1:]) ** 2).sum()
    return error
