"""Fault decisions: compare a step's energy with a calibrated threshold, and isolate.

Detection: the step is faulty when its energy exceeds a threshold calibrated on normal
episodes at a chosen false-positive rate. Three kinds: ``step``, one threshold that that
fraction of normal steps exceed (the paper's percentile); ``per_step``, a time-varying
one per step; ``episode``, one that the peak energy of that fraction of normal episodes
exceeds. A monitor cares how often a normal episode raises an alarm, and with 15 chances
per episode the first two flag several times their rate of whole episodes, so
``episode`` is the default. Isolation: the joint whose channel has the largest
absolute (precision-weighted, when the energy is) prediction error, as in the paper.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from typing import Literal, Sequence

import numpy as np

from neural_asm.models.calibration import Calibration
from neural_asm.models.scoring import StepScore

JOINT_PREFIX = "joint"
ThresholdKind = Literal["step", "per_step", "episode"]
THRESHOLD_KINDS: tuple[str, ...] = ("step", "per_step", "episode")
_TABLES = {"step": "thresholds", "per_step": "step_thresholds", "episode": "episode_thresholds"}  # in Calibration


def joint_channels(channel_names: Sequence[str]) -> list[int]:
    """Indices of the joint-angle channels (named joint1..joint7)."""
    return list(_joint_index(tuple(channel_names)))


@functools.lru_cache(maxsize=64)
def _joint_index(channel_names: tuple[str, ...]) -> tuple[int, ...]:
    return tuple(i for i, n in enumerate(channel_names) if n.startswith(JOINT_PREFIX))


@functools.lru_cache(maxsize=64)
def _name_array(channel_names: tuple[str, ...]) -> np.ndarray:
    names = np.array(channel_names, dtype=object)
    names.flags.writeable = False
    return names


@dataclass(frozen=True)
class FaultDecision:
    fault: bool
    energy: float
    threshold: float
    isolated_joint: str | None  # name of the joint channel with the largest |error|
    ranked_channels: list[str]  # every channel's name, largest |weighted error| first
    ranked_errors: list[float]  # their |weighted error|s, in that order


def threshold_for(calibration: Calibration, fpr: float, step: int, kind: ThresholdKind = "episode") -> float:
    if kind not in _TABLES:
        raise ValueError(f"threshold kind must be one of {THRESHOLD_KINDS}, got {kind!r}")
    table = getattr(calibration, _TABLES[kind])
    if fpr not in table:
        raise KeyError(f"no threshold at false-positive rate {fpr}; calibrated: {sorted(table)}")
    if kind == "per_step":
        steps = table[fpr]
        return float(steps[min(step, len(steps) - 1)])
    return float(table[fpr])


def is_fault(energy: float | np.ndarray, threshold: float | np.ndarray) -> bool | np.ndarray:
    """The decision rule: a step is faulty when its energy is strictly above its threshold. The
    served step (``decide_rows``) and an episode scored whole (``flag_steps``) both apply it."""
    return energy > threshold


def flag_steps(energies: np.ndarray, calibration: Calibration, fpr: float,
               kind: ThresholdKind = "episode") -> tuple[np.ndarray, np.ndarray]:
    """(N, T) flags of whole episodes' energies (N, T) and the (T,) thresholds they were held
    to: what a session of the service would decide at each step, with the same rule."""
    thresholds = np.array([threshold_for(calibration, fpr, t, kind) for t in range(energies.shape[-1])])
    return is_fault(energies, thresholds), thresholds


def isolated_joint(weighted_errors: np.ndarray, channel_names: Sequence[str]) -> np.ndarray:
    """Position (0-based, among the joint channels) of the joint with the largest |error|, for
    errors (..., D) of any leading shape: the fault sweep uses this, the served decision (`isolate_rows`) the
    same argmax of the magnitudes it has."""
    joints = _joint_index(tuple(channel_names))
    if not joints:
        raise ValueError("no joint channels (named joint...) to isolate a fault in")
    return np.abs(weighted_errors[..., list(joints)]).argmax(axis=-1)


def isolate(
    weighted_errors: np.ndarray, channel_names: Sequence[str]
) -> tuple[str | None, list[str], list[float]]:
    """The isolated joint's name (None without joint channels), and every channel's name and
    |error|, largest first."""
    isolated, ranked, errors = isolate_rows(np.asarray(weighted_errors)[None], channel_names)
    return isolated[0], ranked[0], errors[0]


def isolate_rows(
    weighted_errors: np.ndarray, channel_names: Sequence[str]
) -> tuple[list[str | None], list[list[str]], list[list[float]]]:
    """``isolate`` for each row of (B, D) errors at once: the service decides a batch of
    sessions' steps together, and one sort of the batch costs what one row's did."""
    names = tuple(channel_names)
    magnitude = np.abs(weighted_errors)
    order = np.argsort(-magnitude, axis=1, kind="stable")
    ranked = _name_array(names)[order].tolist()
    errors = magnitude[np.arange(len(order))[:, None], order].tolist()
    joints = _joint_index(names)
    if not joints:
        return [None] * len(ranked), ranked, errors
    isolated = [names[joints[j]] for j in magnitude[:, joints].argmax(axis=1).tolist()]  # `isolated_joint`'s
    return isolated, ranked, errors


def decide_rows(
    scores: Sequence[StepScore],
    calibrations: Sequence[Calibration],
    channel_names: Sequence[str],
    fprs: Sequence[float],
    kinds: Sequence[ThresholdKind],
) -> list[FaultDecision]:
    """The fault decision of each step of a batch, each with its own calibration, rate and threshold kind."""
    if not scores:
        return []
    isolated, ranked, errors = isolate_rows(np.array([s.weighted_errors for s in scores]), channel_names)
    decisions = []
    for s, cal, fpr, kind, joint, names, sizes in zip(scores, calibrations, fprs, kinds, isolated, ranked, errors):
        threshold = threshold_for(cal, fpr, s.step, kind)
        decisions.append(FaultDecision(bool(is_fault(s.energy, threshold)), s.energy, threshold, joint, names, sizes))
    return decisions

