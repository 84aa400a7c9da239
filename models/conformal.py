"""Alarm thresholds with a finite-sample false-alarm guarantee, and the statistics to report them.

Split-conformal calibration (Vovk et al.; Angelopoulos & Bates 2023): with n calibration
episode scores exchangeable with a new normal episode's score S, the threshold
q = the ceil((n+1)(1-alpha))-th smallest calibration score gives P(S > q) <= alpha, whatever
the score's distribution; for continuous scores the flag rate is also >= alpha - 1/(n+1).

``TimeVaryingThreshold`` keeps that episode-level guarantee with a threshold that follows the
normal energy along the episode (FAIL-Detect, Xu et al. 2025): per-step scales s_t are fixed on
one split, the episode score max_t E_t / s_t is calibrated on another, and step t alarms when
E_t > q * s_t, i.e. exactly when the episode score exceeds q.
"""

from __future__ import annotations

import math

import numpy as np
from scipy import stats


def _check_alpha(alpha: float) -> float:
    if not (isinstance(alpha, (int, float)) and 0.0 < alpha < 1.0):
        raise ValueError(f"alpha must be a number in (0, 1), got {alpha!r}")
    return float(alpha)


def _check_finite(values: np.ndarray, name: str, ndim: int) -> np.ndarray:
    arr = np.asarray(values, dtype=np.float64)
    if arr.ndim != ndim:
        raise ValueError(f"{name} must be {ndim}-D, got shape {arr.shape}")
    if arr.size == 0:
        raise ValueError(f"{name} is empty")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} contains NaN or infinite values")
    return arr


def conformal_rank(n: int, alpha: float) -> int:
    """1-based rank ceil((n+1)(1-alpha)) of the calibration score used as threshold."""
    # The small tolerance keeps e.g. (99+1)*(1-0.01) = 99.00000000000001 at rank 99.
    return math.ceil((n + 1) * (1.0 - _check_alpha(alpha)) - 1e-9)


def episode_threshold(cal_scores: np.ndarray, alpha: float) -> float:
    """Split-conformal threshold: a new normal episode scores above it with probability <= alpha.

    Flag an episode when its score is strictly greater than the threshold. When
    ceil((n+1)(1-alpha)) > n (fewer than 1/alpha - 1 calibration episodes) no calibration
    score is high enough to keep the guarantee, and the threshold is +inf (never flag).
    """
    scores = _check_finite(cal_scores, "cal_scores", 1)
    k = conformal_rank(len(scores), alpha)
    if k > len(scores):
        return math.inf
    return float(np.partition(scores, k - 1)[k - 1])


class TimeVaryingThreshold:
    """Per-step thresholds q * s_t with the episode-level split-conformal guarantee."""

    def __init__(self, scale_quantile: float = 0.95, floor_fraction: float = 0.05) -> None:
        if not 0.0 < scale_quantile <= 1.0:
            raise ValueError(f"scale_quantile must be in (0, 1], got {scale_quantile!r}")
        if not 0.0 < floor_fraction <= 1.0:
            raise ValueError(f"floor_fraction must be in (0, 1], got {floor_fraction!r}")
        self.scale_quantile = scale_quantile
        self.floor_fraction = floor_fraction
        self.scales: np.ndarray | None = None  # (T,) s_t
        self.quantile: float | None = None  # q

    def fit(self, scale_energies: np.ndarray, cal_energies: np.ndarray, alpha: float) -> "TimeVaryingThreshold":
        """Scales from one split of normal episodes (N1, T), q from a disjoint split (N2, T).

        s_t is the scale_quantile of step t's energies, floored at floor_fraction times the
        median s_t so that a step where normal energy is almost zero cannot make every tiny
        deviation an alarm (and a zero scale cannot divide).
        """
        scale = _check_finite(scale_energies, "scale_energies", 2)
        cal = _check_finite(cal_energies, "cal_energies", 2)
        if scale.shape[1] != cal.shape[1]:
            raise ValueError(f"scale_energies has {scale.shape[1]} steps, cal_energies {cal.shape[1]}")
        raw = np.quantile(scale, self.scale_quantile, axis=0)
        floor = max(self.floor_fraction * float(np.median(raw)), np.finfo(np.float64).tiny)
        self.scales = np.maximum(raw, floor)
        self.quantile = episode_threshold((cal / self.scales).max(axis=1), alpha)
        return self

    @property
    def thresholds(self) -> np.ndarray:
        """(T,) energy threshold of every step."""
        if self.scales is None or self.quantile is None:
            raise RuntimeError("TimeVaryingThreshold is not fitted: call fit() first")
        return self.quantile * self.scales

    def flags(self, energies: np.ndarray) -> np.ndarray:
        """(N, T) bool, energy above its step's threshold; T may be shorter than fitted (online)."""
        thresholds = self.thresholds
        e = _check_finite(energies, "energies", 2)
        if e.shape[1] > len(thresholds):
            raise ValueError(f"energies have {e.shape[1]} steps, thresholds only {len(thresholds)}")
        return e > thresholds[: e.shape[1]]

    def first_crossing(self, energies: np.ndarray, from_step: int = 0) -> np.ndarray:
        """(N,) first step >= from_step whose energy crosses its threshold, -1 if none."""
        if not from_step >= 0:
            raise ValueError(f"from_step must be >= 0, got {from_step}")
        flags = self.flags(energies)
        flags[:, :from_step] = False
        return np.where(flags.any(axis=1), flags.argmax(axis=1), -1)


def binomial_interval(k: int, n: int, level: float = 0.95) -> tuple[float, float]:
    """Clopper-Pearson (exact) interval of a rate measured as k successes in n trials."""
    if not (isinstance(n, (int, np.integer)) and n >= 1):
        raise ValueError(f"n must be an integer >= 1, got {n!r}")
    if not (isinstance(k, (int, np.integer)) and 0 <= k <= n):
        raise ValueError(f"k must be an integer in [0, n={n}], got {k!r}")
    if not 0.0 < level < 1.0:
        raise ValueError(f"level must be in (0, 1), got {level!r}")
    ci = stats.binomtest(int(k), int(n)).proportion_ci(confidence_level=level, method="exact")
    return float(ci.low), float(ci.high)


def mcnemar_exact(a_only: int, b_only: int) -> float:
    """Two-sided exact McNemar p-value from the discordant pairs (a right and b wrong, and back)."""
    for name, value in (("a_only", a_only), ("b_only", b_only)):
        if not (isinstance(value, (int, np.integer)) and value >= 0):
            raise ValueError(f"{name} must be an integer >= 0, got {value!r}")
    if a_only + b_only == 0:
        return 1.0
    return float(stats.binomtest(int(a_only), int(a_only + b_only), 0.5).pvalue)
