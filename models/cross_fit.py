"""Thresholds from more normal episodes than were held out: cross-fitting.

A 1 % split-conformal threshold needs at least 99 normal episodes; below that it is their highest
peak and promises no rate (``conformal_episode_threshold``). The demonstrations a memory was
trained on are normal episodes too, but its own energies on them are optimistic. Cross-fitting
scores each demonstration with a network that did not learn it: the demonstrations are cut into
folds (the episodes of one group, a recorded run, never on both sides), and a network trained as
the memory was on all folds but one, and calibrated on the same precision episodes, scores the
fold left out. Those out-of-fold energies join the held-out episodes' when the thresholds are set.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from tqdm.auto import tqdm

from neural_asm.models.asm import NeuralASM
from neural_asm.models.calibration import estimate
from neural_asm.models.config import SCORING
from neural_asm.models.normaliser import Normaliser
from neural_asm.models.plan import check_demonstrations


def conformal_minimum(fpr: float = SCORING.default_fpr) -> int:
    """The fewest normal episodes whose peaks give a split-conformal threshold at ``fpr`` (99 at the
    served 1 %): below it the threshold is their highest peak, and cross-fitting adds episodes."""
    return math.ceil(1 / fpr - 1)


def group_folds(groups: Sequence[object] | np.ndarray, folds: int, seed: int) -> np.ndarray:
    """Each episode's fold (0..folds-1): its group's, the groups shuffled with ``seed`` and dealt
    out in turn, so that no group is on both sides of a fold."""
    names = np.asarray(groups).astype(str)
    unique = np.array(sorted(set(names.tolist())))
    if not 2 <= folds <= len(unique):
        raise ValueError(f"cross-fitting needs 2 <= folds <= the number of groups ({len(unique)} among {len(names)} "
                         f"demonstrations), got {folds}")
    fold_of = dict(zip(unique[np.random.default_rng(seed).permutation(len(unique))], np.arange(len(unique)) % folds))
    return np.array([fold_of[name] for name in names], dtype=int)


def out_of_fold_energies(
    model: NeuralASM,
    demonstrations: np.ndarray,
    labels: np.ndarray | None,
    precision: np.ndarray,
    precision_labels: Sequence[str] | None,
    modes: Sequence[str],
    fold: np.ndarray,
    progress: bool = True,
) -> dict[str, np.ndarray]:
    """Energies (N, T) of every demonstration in each recall mode of ``modes``, each from a network
    trained as ``model`` was (for the epochs it kept) on the demonstrations outside its ``fold`` and
    calibrated on the ``precision`` episodes as ``model``'s calibration of the mode is (mean errors
    taken out where it takes them out). Fold networks fit a plan memory only when plan recall is
    among ``modes``."""
    if len(fold) != len(demonstrations):
        raise ValueError(f"{len(fold)} fold numbers for {len(demonstrations)} demonstrations")
    served = {mode: model.calibration(mode, 1) for mode in modes}
    missing = [mode for mode, cal in served.items() if cal is None]
    if missing:
        raise ValueError(f"the memory has no {', '.join(missing)} calibration to cross-fit")
    epochs = int(model.provenance.get("kept_epoch", model.config.epochs))
    config = model.config.with_(plan_memory="plan" in modes, epochs=epochs)
    energies = {mode: np.empty(demonstrations.shape[:2]) for mode in modes}
    for k in tqdm(sorted(set(fold.tolist())), desc="cross-fitting", unit="fold", disable=not progress):
        inside = fold != k
        network = NeuralASM.fit(demonstrations[inside], model.channel_names, config, progress=False,
                                labels=None if labels is None else labels[inside],
                                context_channels=model.context_channels, rate_hz=model.rate_hz)
        for mode, cal in served.items():
            assert cal is not None  # checked above
            covariance = "full" if cal.error_precision is not None else "diagonal"
            calibration = estimate(mode, 1, network.errors(precision, mode), "precision episodes", covariance,
                                   SCORING.spread_floor(model.rate_hz), cal.error_mean is not None,
                                   precision_labels)
            energies[mode][~inside] = calibration.energy(network.errors(demonstrations[~inside], mode))
    return energies


@dataclass(frozen=True)
class CrossFit:
    """How ``SkillMemory.calibrate`` cross-fits: the raw demonstrations (N, T, D) the memory was
    trained on and their skills, cut into ``folds`` by ``groups`` (each demonstration's run or
    recording; None: each demonstration its own), dealt with ``seed``."""

    demonstrations: np.ndarray
    labels: np.ndarray | None = None
    folds: int = 5
    groups: Sequence[object] | np.ndarray | None = None
    seed: int = 0

    def folds_for(self, model: NeuralASM, steps: int) -> np.ndarray:
        """Each demonstration's fold, once everything cross-fitting ``model`` needs is checked (before
        anything is trained or changed): a ValueError names what is wrong."""
        data = self._data()
        if data.ndim != 3 or data.shape[2] != model.obs_size:
            raise ValueError(f"cross-fitting needs the demonstrations as (N, T, {model.obs_size}), got {data.shape}")
        if data.shape[1] != steps:
            raise ValueError(f"cross-fitting pools energies step by step: the demonstrations have {data.shape[1]} "
                             f"steps, the threshold episodes {steps}")
        fitted = Normaliser.fit(data)
        trained = model.provenance.get("sequences", len(data))
        if trained != len(data) or not (np.allclose(fitted.mean, model.normaliser.mean, rtol=1e-4, atol=1e-9)
                                        and np.allclose(fitted.std, model.normaliser.std, rtol=1e-4, atol=1e-9)):
            raise ValueError(f"cross-fitting needs the demonstrations the memory was trained on ({trained} "
                             f"sequences); these {len(data)} are not: their count, channel means or spreads differ")
        skills = model.provenance.get("skills", [])
        labels = self._labels()
        if labels is None and len(skills) > 1:
            raise ValueError(f"the memory learnt the skills {skills}: cross-fitting needs each demonstration's skill")
        if labels is not None and len(labels) != len(data):
            raise ValueError(f"{len(labels)} skill labels for {len(data)} demonstrations")
        groups = np.arange(len(data)) if self.groups is None else np.asarray(self.groups)
        if len(groups) != len(data):
            raise ValueError(f"{len(groups)} groups for {len(data)} demonstrations")
        fold = group_folds(groups, self.folds, self.seed)
        if model.plan is not None:  # each fold network fits a plan memory on the other folds
            for k in range(self.folds):
                try:
                    check_demonstrations(["all"] * int((fold != k).sum()) if labels is None else labels[fold != k])
                except ValueError as exc:
                    raise ValueError(f"fold {k + 1} of {self.folds} left out: {exc}; use fewer folds") from None
        return fold

    def energies(self, model: NeuralASM, precision: np.ndarray, precision_labels: Sequence[str] | None,
                 fold: np.ndarray, progress: bool = True) -> dict[str, np.ndarray]:
        """Out-of-fold energies (N, T) of the demonstrations in each of the model's recall modes,
        ``fold`` from `folds_for`."""
        return out_of_fold_energies(model, self._data(), self._labels(), precision, precision_labels,
                                    model.recall_modes, fold, progress)

    def _data(self) -> np.ndarray:
        return np.asarray(self.demonstrations, np.float64)

    def _labels(self) -> np.ndarray | None:
        return None if self.labels is None else np.asarray(self.labels)
