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

from dataclasses import dataclass
from typing import Literal, Sequence

import numpy as np

from models.calibration import Calibration
from models.scoring import StepScore

JOINT_PREFIX = "joint"
ThresholdKind = Literal["step", "per_step", "episode"]
THRESHOLD_KINDS: tuple[str, ...] = ("step", "per_step", "episode")


def joint_channels(channel_names: Sequence[str]) -> list[int]:
    """Indices of the joint-angle channels (named joint1..joint7)."""
    return [i for i, n in enumerate(channel_names) if n.startswith(JOINT_PREFIX)]


@dataclass(frozen=True)
class FaultDecision:
    fault: bool
    energy: float
    threshold: float
    isolated_joint: str | None  # name of the joint channel with the largest |error|
    ranked_channels: list[tuple[str, float]]  # (name, |weighted error|), largest first


def threshold_for(calibration: Calibration, fpr: float, step: int, kind: ThresholdKind = "episode") -> float:
    tables = {"step": calibration.thresholds, "per_step": calibration.step_thresholds,
              "episode": calibration.episode_thresholds}
    if kind not in tables:
        raise ValueError(f"threshold kind must be one of {THRESHOLD_KINDS}, got {kind!r}")
    table = tables[kind]
    if fpr not in table:
        raise KeyError(f"no threshold at false-positive rate {fpr}; calibrated: {sorted(table)}")
    if kind == "per_step":
        steps = table[fpr]
        return float(steps[min(step, len(steps) - 1)])
    return float(table[fpr])


def isolated_joint(weighted_errors: np.ndarray, channel_names: Sequence[str]) -> np.ndarray:
    """Position (0-based, among the joint channels) of the joint with the largest |error|, for
    errors (..., D) of any leading shape: the served decision and the fault sweep use this."""
    joints = joint_channels(channel_names)
    if not joints:
        raise ValueError("no joint channels (named joint...) to isolate a fault in")
    return np.abs(weighted_errors[..., joints]).argmax(axis=-1)


def isolate(weighted_errors: np.ndarray, channel_names: Sequence[str]) -> tuple[str | None, list[tuple[str, float]]]:
    """The isolated joint's name (None without joint channels) and every channel ranked by |error|."""
    magnitude = np.abs(weighted_errors)
    order = np.argsort(-magnitude, kind="stable")
    ranked = list(zip([channel_names[i] for i in order.tolist()], magnitude[order].tolist()))
    joints = joint_channels(channel_names)
    isolated = channel_names[joints[int(isolated_joint(weighted_errors, channel_names))]] if joints else None
    return isolated, ranked


def decide(
    score: StepScore,
    calibration: Calibration,
    channel_names: Sequence[str],
    fpr: float = 0.01,
    kind: ThresholdKind = "episode",
) -> FaultDecision:
    threshold = threshold_for(calibration, fpr, score.step, kind)
    isolated, ranked = isolate(score.weighted_errors, channel_names)
    return FaultDecision(score.energy > threshold, score.energy, threshold, isolated, ranked)
