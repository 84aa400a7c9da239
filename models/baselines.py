"""Simple references the Neural ASM must beat, all on normalised sequences (N, T, D).

- ``StepStatistics``: per-step mean and spread of demonstrations, the associative
  memory of classic ASMs (Pastor et al.) and the paper's z-score baseline. Pooled over
  all skills it is skill-agnostic; per skill, the skill is selected explicitly by the
  nearest first observation.
- ``LinearOneStep``: ridge regression of x[t+1] on x[t], a strong one-step predictor.

Each exposes ``expected(sequences) -> (N, T, D)``, what it expects of every step, so
errors, energies and thresholds are computed exactly as for the Neural ASM.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class StepStatistics:
    means: np.ndarray  # (S, T, D) per library entry
    stds: np.ndarray  # (S, T, D)

    @classmethod
    def fit(cls, sequences: np.ndarray, labels: np.ndarray | None = None) -> "StepStatistics":
        """One entry per distinct label, or a single pooled entry when labels is None."""
        groups = [sequences] if labels is None else [sequences[labels == k] for k in np.unique(labels)]
        return cls(np.stack([g.mean(0) for g in groups]), np.stack([g.std(0) for g in groups]))

    def select(self, sequences: np.ndarray) -> np.ndarray:
        """Library entry of each sequence: nearest mean first observation (explicit recognition)."""
        d = ((sequences[:, None, 0] - self.means[None, :, 0]) ** 2).sum(-1)
        return d.argmin(axis=1)

    def expected(self, sequences: np.ndarray) -> np.ndarray:
        return self.means[self.select(sequences)][:, : sequences.shape[1]]

    def spread(self, sequences: np.ndarray) -> np.ndarray:
        """The selected entry's per-step std (N, T, D): the z-score denominator."""
        return self.stds[self.select(sequences)][:, : sequences.shape[1]]


@dataclass(frozen=True)
class LinearOneStep:
    weights: np.ndarray  # (D + 1, D): x[t+1] = [x[t], 1] @ weights

    @classmethod
    def fit(cls, sequences: np.ndarray, ridge: float = 1e-2) -> "LinearOneStep":
        x = sequences[:, :-1].reshape(-1, sequences.shape[-1])
        y = sequences[:, 1:].reshape(-1, sequences.shape[-1])
        a = np.hstack([x, np.ones((len(x), 1))])
        reg = ridge * np.eye(a.shape[1])
        reg[-1, -1] = 0.0  # do not shrink the bias
        return cls(np.linalg.solve(a.T @ a + reg, a.T @ y))

    def step(self, x: np.ndarray) -> np.ndarray:
        return np.concatenate([x, np.ones(x.shape[:-1] + (1,))], axis=-1) @ self.weights

    def expected(self, sequences: np.ndarray) -> np.ndarray:
        """Step 0 is its own expectation (a cue, as for the network); then one-step predictions."""
        return np.concatenate([sequences[:, :1], self.step(sequences[:, :-1])], axis=1)

    def rollout(self, cue: np.ndarray, horizon: int) -> np.ndarray:
        """Offline roll-out from the last cue observation (N, T_n, D) -> (N, horizon, D)."""
        out = list(np.moveaxis(cue, 1, 0))
        while len(out) < horizon:
            out.append(self.step(out[-1]))
        return np.stack(out, axis=1)
