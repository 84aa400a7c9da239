"""What is measured on a recalled motor plan."""

from __future__ import annotations

import numpy as np

from neural_asm.experiments.contextual.config import ContextualConfig


def lateral_deviation(hand: np.ndarray, cfg: ContextualConfig) -> np.ndarray:
    """Signed distance (..., T) of hand positions (..., T, 2) from the S->T line, + = left."""
    start = np.asarray(cfg.start_xy)
    axis = np.asarray(cfg.target_xy) - start
    axis = axis / np.linalg.norm(axis)
    rel = hand - start
    return axis[0] * rel[..., 1] - axis[1] * rel[..., 0]


def pead(hand: np.ndarray, cfg: ContextualConfig) -> np.ndarray:
    """Post-exposure absolute deviation (N,), signed: the largest deviation from S->T.

    Only the reach to T counts: the follow-through to a secondary target leaves the
    line by design, and Sheahan et al. measure the movement to the central target.
    The sign is kept so that plans for the two cues can be seen to bow apart.
    """
    dev = lateral_deviation(hand[:, : cfg.reach_steps], cfg)
    worst = np.abs(dev).argmax(axis=1)
    return dev[np.arange(len(dev)), worst]


def recall_error(recalled: np.ndarray, truth: np.ndarray) -> float:
    """Mean squared error over steps 1..T-1 (step 0 is the cue), normalised units."""
    return float(np.mean((recalled[:, 1:] - truth[:, 1:]) ** 2))
