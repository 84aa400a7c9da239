"""Per-channel z-scoring with statistics of the training demonstrations (paper, Methods)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

# A channel that never varies in the demonstrations (e.g. a toggle that stays 0) would
# otherwise get an infinite gain; this floor is in the channel's own units.
STD_FLOOR = 1e-6


@dataclass(frozen=True)
class Normaliser:
    mean: np.ndarray  # (D,)
    std: np.ndarray  # (D,)

    @classmethod
    def fit(cls, sequences: np.ndarray) -> "Normaliser":
        flat = np.asarray(sequences, np.float64).reshape(-1, sequences.shape[-1])
        return cls(flat.mean(axis=0), np.maximum(flat.std(axis=0), STD_FLOOR))

    def normalise(self, x: np.ndarray) -> np.ndarray:
        return ((np.asarray(x, np.float64) - self.mean) / self.std).astype(np.float32)

    def denormalise(self, x: np.ndarray) -> np.ndarray:
        return np.asarray(x, np.float64) * self.std + self.mean
