"""Precisions and fault thresholds from normal episodes.

A calibration belongs to one recall setting (mode, cue length). It holds the expected
spread of each channel's normalised prediction error at each step and, optionally, the
precision matrix of the errors divided by those spreads at each step (together, the
precisions of the observation layer), at some rates each skill's mean error at each step (what
the expectation gets wrong on every normal episode of the skill alike, taken out before
weighing: see `Calibration.centre`), and energy thresholds at chosen false-positive rates: one
for all steps, one per step, and one for an episode's peak energy. Spreads and thresholds
should come from different normal episodes; estimating both on the same ones makes
the measured false-positive rate optimistic.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from sklearn.covariance import LedoitWolf

from neural_asm.models.config import SCORING, Covariance
from neural_asm.models.conformal import episode_threshold
from neural_asm.models.scoring import quadratic, step_rows


@dataclass
class Calibration:
    mode: str
    cue_steps: int
    error_std: np.ndarray  # (T, D), normalised units
    source: str  # where the spreads and thresholds came from, for provenance
    # (T, D, D) precision matrices of error / error_std; None: channels independent
    error_precision: np.ndarray | None = None
    thresholds: dict[float, float] = field(default_factory=dict)
    step_thresholds: dict[float, np.ndarray] = field(default_factory=dict)
    episode_thresholds: dict[float, float] = field(default_factory=dict)
    # (S, T, D) each skill's mean error per step; None: errors taken as centred
    error_mean: np.ndarray | None = None
    skills: tuple[str, ...] = ()  # whose means error_mean's rows are

    @property
    def key(self) -> str:
        return calibration_key(self.mode, self.cue_steps)

    def centre(self, errors: np.ndarray, told: Sequence[str] | None = None) -> np.ndarray:
        """Errors (..., T, D) of whole episodes less, at each step, the mean error of the skill
        whose means explain the episode's steps before it best (the least sum of squared errors
        divided by their spreads; before any, the skills' average): the memory recognises the
        skill by its systematic errors, as a session does step by step (`centre_step`).

        ``told``: each episode's skill (N,), whose mean errors are taken out at every step instead:
        an oracle that knows what a session does not, measuring what recognition costs (a skill
        without mean errors here gets the skills' average)."""
        if self.error_mean is None:
            return errors.astype(np.float64)
        steps, width = errors.shape[-2:]
        flat = errors.reshape(-1, steps, width).astype(np.float64)
        if told is None:
            pick = self.recognised(flat)
        else:
            index = [self.skills.index(s) if s in self.skills else -1 for s in np.asarray(told).astype(str)]
            pick = np.repeat(np.array(index)[:, None], steps, axis=1)
        return (flat - self._means_at(np.arange(steps))[pick, np.arange(steps)]).reshape(errors.shape)

    def recognised(self, errors: np.ndarray) -> np.ndarray:
        """(N, T) the skill (index into `skills`) whose mean errors explain each episode's steps
        before each step best; -1 at the first step, before any (the skills' average is used)."""
        steps = errors.shape[-2]
        means = self._means_at(np.arange(steps))
        misfit = (((errors[:, None] - means[None, :-1]) / step_rows(self.error_std, steps)) ** 2).sum(-1)  # (N, S, T)
        before = np.cumsum(misfit, axis=2)[..., :-1]
        return np.concatenate([np.full((len(errors), 1), -1), before.argmin(axis=1)], axis=1)

    def centre_step(self, errors: np.ndarray, steps: np.ndarray, misfit: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """One step (B, D) of streams at `steps` (B,), less each stream's recognised skill's mean
        error, given each skill's misfit to the stream's steps so far (B, S); and the misfits
        with this step added. What `centre` does to whole episodes."""
        if self.error_mean is None:
            return errors, misfit
        means = self._means_at(steps)
        pick = self.pick(steps, misfit)
        spread = self.error_std[np.minimum(steps, len(self.error_std) - 1)]
        added = (((errors[None] - means[:-1]) / spread[None]) ** 2).sum(-1).T  # (B, S)
        return errors - means[pick, np.arange(len(errors))], misfit + added

    def pick(self, steps: np.ndarray, misfit: np.ndarray) -> np.ndarray:
        """(B,) the skill (index into `skills`; -1 at the first step, before any) whose mean errors
        centre each stream's step at `steps` (B,), given each skill's misfit to its steps before (B, S)."""
        return np.where(steps == 0, -1, misfit.argmin(axis=1))

    def _means_at(self, steps: np.ndarray) -> np.ndarray:
        """Each skill's mean error at `steps` and, last, the skills' average (S + 1, len(steps), D):
        row -1 is what a step loses before any step has shown the skill."""
        means = self.error_mean[:, np.minimum(steps, len(self.error_std) - 1)]
        return np.concatenate([means, means.mean(axis=0, keepdims=True)])

    def weigh(self, errors: np.ndarray, told: Sequence[str] | None = None) -> np.ndarray:
        """Normalised errors (..., T, D), centred (`centre`), divided by their spreads: what the
        energy whitens and what isolation ranks."""
        return self.centre(errors, told) / step_rows(self.error_std, errors.shape[-2])

    def energy(self, errors: np.ndarray, told: Sequence[str] | None = None) -> np.ndarray:
        """Energy per step (..., T) of normalised errors (..., T, D) (``told``: see `centre`)."""
        precision = None if self.error_precision is None else step_rows(self.error_precision, errors.shape[-2])
        return quadratic(self.weigh(errors, told), precision)


@dataclass(frozen=True)
class Weighting:
    """How a calibration weighs errors: a full precision matrix per step or one spread per
    channel (``covariance``), and whether each skill's mean error is taken out, the skill
    recognised as a session recognises it (``centred``; None: the rate's default,
    `ScoringConfig.centres_errors`)."""

    covariance: Covariance = SCORING.error_covariance
    centred: bool | None = None


def calibration_key(mode: str, cue_steps: int) -> str:
    return f"{mode}:{cue_steps}"


def error_spread(errors: np.ndarray, floor: float = SCORING.error_std_floor) -> np.ndarray:
    """Per-step, per-channel RMS of normalised errors (N, T, D) -> (T, D), floored."""
    rms = np.sqrt((errors.astype(np.float64) ** 2).mean(axis=0))
    return np.maximum(rms, floor)


def error_precision(errors: np.ndarray, error_std: np.ndarray) -> np.ndarray:
    """Per-step precision matrices (T, D, D) of normalised errors (N, T, D) divided by
    their spreads: the inverse of their second moment about zero (as the spreads are),
    shrunk by Ledoit-Wolf towards a multiple of the identity, since a few hundred episodes
    do not pin down a D x D matrix and channels that never vary would make it singular."""
    if len(errors) < 2:
        raise ValueError(f"precision matrices need errors of at least 2 episodes, got {len(errors)}")
    w = errors.astype(np.float64) / error_std[None, : errors.shape[1]]
    return np.stack([LedoitWolf(assume_centered=True).fit(w[:, t]).precision_ for t in range(w.shape[1])])


def estimate(
    mode: str, cue_steps: int, errors: np.ndarray, source: str, covariance: Covariance = SCORING.error_covariance,
    floor: float = SCORING.error_std_floor, centred: bool = False, labels: Sequence[str] | None = None,
) -> Calibration:
    """Precisions (no thresholds yet) from normalised errors (N, T, D) of normal episodes; the
    spreads floored at `floor` (`ScoringConfig.spread_floor` of the episodes' rate). With
    `centred` (`ScoringConfig.centres_errors` of the rate), each skill's mean error per step is
    kept (the episodes' `labels`; without them, one mean for all) and the spreads and precisions
    are those of the errors centred as `Calibration.centre` centres them."""
    if covariance not in ("full", "diagonal"):
        raise ValueError(f"covariance must be 'full' or 'diagonal', got {covariance!r}")
    if labels is not None and len(labels) != len(errors):
        raise ValueError(f"{len(labels)} skill labels for {len(errors)} episodes")
    mean, skills, residual = None, (), errors
    if centred:
        names = np.full(len(errors), "all") if labels is None else np.asarray(labels).astype(str)
        unique, index = np.unique(names, return_inverse=True)
        skills = tuple(str(name) for name in unique)
        mean = np.stack([errors[index == i].astype(np.float64).mean(axis=0) for i in range(len(skills))])
        # The spreads are those of the errors as sessions centre them, the skill recognised (by
        # the spreads about each episode's own skill's mean): at the first step, before any
        # recognition, the errors less the skills' average spread wider.
        recognising = Calibration(mode, cue_steps, error_spread(errors - mean[index], floor), source,
                                  error_mean=mean, skills=skills)
        residual = recognising.centre(errors)
    spread = error_spread(residual, floor)
    precision = error_precision(residual, spread) if covariance == "full" else None
    return Calibration(mode, cue_steps, spread, source, precision, error_mean=mean, skills=skills)


def quantile_threshold(energies: np.ndarray, fpr: float) -> float:
    """Energy above which a fraction ``fpr`` of the given normal energies lie."""
    if not 0 < fpr < 1:
        raise ValueError(f"false-positive rate must be in (0, 1), got {fpr}")
    return float(np.quantile(energies, 1.0 - fpr, method="higher"))


def conformal_episode_threshold(peaks: np.ndarray, fpr: float) -> float:
    """The split-conformal threshold of episode peaks (`models.conformal`): a new normal episode
    peaks above it with probability <= fpr. With fewer than 1/fpr - 1 episodes no peak is high
    enough for that guarantee; the highest is used (`nasm calibrate` warns of it)."""
    threshold = episode_threshold(peaks, fpr)
    return threshold if math.isfinite(threshold) else float(np.max(peaks))


@dataclass(frozen=True)
class Thresholds:
    """The three thresholds at one false-positive rate, from normal energies (N, T): one for
    every step, one per step (quantiles of step energies), and one for an episode's peak energy
    (split-conformal: np.quantile's "higher" rank falls one short of it at 150 episodes, and
    flagged 1.4 % of normal episodes on average over re-splits where 1 % was asked)."""

    step: float
    per_step: np.ndarray  # (T,)
    episode: float

    @classmethod
    def of(cls, energies: np.ndarray, fpr: float) -> Thresholds:
        return cls(
            quantile_threshold(energies, fpr),
            np.array([quantile_threshold(energies[:, t], fpr) for t in range(energies.shape[1])]),
            conformal_episode_threshold(energies.max(axis=1), fpr),
        )


def set_thresholds(
    calibration: Calibration,
    errors: np.ndarray,
    fprs: tuple[float, ...] = SCORING.fprs,
) -> None:
    """Thresholds from normalised errors (N, T, D) of normal episodes, weighted energy."""
    set_energy_thresholds(calibration, calibration.energy(errors), fprs)


def set_energy_thresholds(calibration: Calibration, energies: np.ndarray,
                          fprs: tuple[float, ...] = SCORING.fprs) -> None:
    """Thresholds from the energies (N, T) of normal episodes (cross-fitting pools several
    networks' energies, each under its own precisions: `models.cross_fit`)."""
    for fpr in fprs:
        t = Thresholds.of(energies, fpr)
        calibration.thresholds[fpr] = t.step
        calibration.step_thresholds[fpr] = t.per_step
        calibration.episode_thresholds[fpr] = t.episode
