"""The paper's z-score rivals: per-step statistics of the demonstrations.

``StepStatistics`` is the associative memory of classic ASMs (Pastor et al.) and the paper's
z-score baseline: per-step mean and spread, pooled over skills (skill-agnostic) or one entry
per skill, selected by the nearest first observation. Each rival here also gives its `spread`,
the demonstrations' per-step std of the entry it uses: the paper's own weighting of errors.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from neural_asm.rivals.base import DetectorBase


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


class PooledZScore(DetectorBase):
    name = "zscore_pooled"
    label = "z-score, pooled over skills (the paper's baseline)"
    pooled = True

    def _fit(self, x: np.ndarray, skills: np.ndarray, seed: int) -> None:
        self.statistics = StepStatistics.fit(x, None if self.pooled else skills)

    def _expected(self, x: np.ndarray, skills: np.ndarray) -> np.ndarray:
        return self.statistics.expected(x)

    def spread(self, x: np.ndarray, skills: np.ndarray) -> np.ndarray:
        return self.statistics.spread(x)


class ClassicASM(PooledZScore):
    """One entry per skill, the skill recognised by the nearest first observation (not told it)."""

    name = "classic_asm"
    label = "classic ASM"
    pooled = False
