"""What every rival shares: the one `Detector` protocol and its input checks.

A detector sees normalised sequences x (N, T, D) and the true skill of each (baselines may
use it: generous to them). Some channels are context (e.g. a perceived cube pose or a place
target); an episode's context is what they read at its first step, c = x[:, 0, context].
``expected(x, skills)`` is causal: expected[:, t] depends on x[:, :t] and c only (a
predictor's expected[:, 0] is x[:, 0] itself), so every method can run online.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Protocol, runtime_checkable

import numpy as np

from neural_asm.models.sequences import checked_array


@runtime_checkable
class Detector(Protocol):
    name: str  # machine name, e.g. "conditional_template"
    label: str  # human name for tables

    def fit(
        self, demos: np.ndarray, skills: np.ndarray, context_channels: Sequence[int], seed: int = 0
    ) -> "Detector": ...

    def expected(self, x: np.ndarray, skills: np.ndarray) -> np.ndarray: ...


@runtime_checkable
class Spread(Protocol):
    """A z-score rival: also the demonstrations' per-step std of what it expects (N, T, D)."""

    def spread(self, x: np.ndarray, skills: np.ndarray) -> np.ndarray: ...


def check_skills(skills: np.ndarray, n: int) -> np.ndarray:
    arr = np.asarray(skills)
    if arr.shape != (n,):
        raise ValueError(f"skills must have shape ({n},), one per sequence, got {arr.shape}")
    return arr.astype(str)


class DetectorBase:
    """Checks shared by every detector; subclasses implement ``_fit`` and ``_expected``."""

    name = ""
    label = ""

    def __init__(self, name: str | None = None) -> None:
        """`name` renames this instance: a benchmark's own name for the rival (its results' keys)."""
        if name is not None:
            self.name = name
        self.skill_names: list[str] = []
        self.context_channels: np.ndarray = np.zeros(0, dtype=int)
        self.steps = 0
        self.dims = 0

    def fit(
        self, demos: np.ndarray, skills: np.ndarray, context_channels: Sequence[int], seed: int = 0
    ) -> "DetectorBase":
        x = checked_array(demos, "demos")
        labels = check_skills(skills, len(x))
        ctx = np.asarray(list(context_channels), dtype=int)
        if ctx.size and (ctx.min() < 0 or ctx.max() >= x.shape[2] or len(set(ctx.tolist())) != ctx.size):
            raise ValueError(f"context_channels must be distinct indices in [0, {x.shape[2]}), got {ctx.tolist()}")
        names, counts = np.unique(labels, return_counts=True)
        if counts.min() < 2:
            raise ValueError(f"every skill needs >= 2 demonstrations; {names[counts.argmin()]!r} has {counts.min()}")
        self.skill_names, self.context_channels = names.tolist(), ctx
        self.steps, self.dims = x.shape[1], x.shape[2]
        self._fit(x, labels, seed)
        return self

    def expected(self, x: np.ndarray, skills: np.ndarray) -> np.ndarray:
        """(N, T, D) expectation of every step; T may be shorter than the demonstrations'."""
        if not self.skill_names:
            raise RuntimeError(f"{type(self).__name__} is not fitted: call fit() first")
        arr = checked_array(x, "x")
        labels = check_skills(skills, len(arr))
        if arr.shape[2] != self.dims:
            raise ValueError(f"x has {arr.shape[2]} channels, the detector was fitted on {self.dims}")
        if arr.shape[1] > self.steps:
            raise ValueError(f"x has {arr.shape[1]} steps, the demonstrations only {self.steps}")
        unknown = sorted(set(labels.tolist()) - set(self.skill_names))
        if unknown:
            raise ValueError(f"unknown skills {unknown}; fitted on {self.skill_names}")
        return self._expected(arr, labels)

    def context(self, x: np.ndarray) -> np.ndarray:
        """(N, C) context of each episode: its context channels at the first step."""
        return x[:, 0, self.context_channels]

    def _fit(self, x: np.ndarray, skills: np.ndarray, seed: int) -> None:
        raise NotImplementedError

    def _expected(self, x: np.ndarray, skills: np.ndarray) -> np.ndarray:
        raise NotImplementedError

