"""What a fault changes: each fault episode against its no-fault twin (same seed, no fault),
whitened by normal variation. One rule for every benchmark of what an oracle could see.

The normal spread is taken per skill, step and channel on held-out normal episodes, floored
at `SPREAD_FLOOR` of the channel's spread over all steps: a channel that never varies at
some step (a gripper held shut) would otherwise make a rounding-level departure "visible".
"""

from __future__ import annotations

import numpy as np

VISIBLE_K = 3.0  # normal standard deviations a departure must exceed to be visible
SPREAD_FLOOR = 1e-3  # fraction of the channel's overall normal spread


def whitened_deviation(faults: np.ndarray, twins: np.ndarray, fault_skills: np.ndarray, normal: np.ndarray,
                       normal_skills: np.ndarray) -> np.ndarray:
    """|fault - twin| (N, T, D) in normal standard deviations of the fault's skill."""
    channel = np.maximum(normal.reshape(-1, normal.shape[-1]).std(axis=0), np.finfo(float).tiny)
    sigma = np.ones_like(faults)
    for skill in np.unique(fault_skills):
        sigma[fault_skills == skill] = np.maximum(normal[normal_skills == skill].std(axis=0), SPREAD_FLOOR * channel)
    return np.abs(faults - twins) / sigma


def onset_steps(faults: np.ndarray, twins: np.ndarray) -> np.ndarray:
    """Each fault's first step that differs from its twin at all (the last step if none)."""
    moved = np.abs(faults - twins).max(axis=2) > 0.0
    return np.where(moved.any(axis=1), moved.argmax(axis=1), faults.shape[1] - 1)


CONSEQUENCES: tuple[str, ...] = ("consequential", "deviating", "invisible", "unattributed")


def consequences(fault_success: np.ndarray, twin_success: np.ndarray, visible: np.ndarray) -> np.ndarray:
    """Each fault by what it did, as robot failure detectors are scored: *consequential* when the
    task fails (the cube ends beyond the success tolerance) where its twin succeeded, *deviating*
    when it is visible but the task succeeds, *invisible* when neither, *unattributed* when the
    twin failed too (the task was lost without the fault). The simulator reports no collisions,
    so a strike that still places the cube is not consequential here."""
    label = np.where(visible, "deviating", "invisible")
    label = np.where(twin_success & ~fault_success, "consequential", label)
    return np.where(twin_success, label, "unattributed")


def first_visible_steps(deviation: np.ndarray, k: float = VISIBLE_K) -> np.ndarray:
    """Each episode's first step at which some channel departs by more than k normal standard
    deviations (-1 if none): from there on a monitor can be asked to see the fault."""
    visible = deviation.max(axis=2) > k
    return np.where(visible.any(axis=1), visible.argmax(axis=1), -1)


def visible_from(deviation: np.ndarray, first_step: np.ndarray, k: float = VISIBLE_K) -> np.ndarray:
    """Whether some channel departs by more than k normal standard deviations at or after `first_step`."""
    steps = np.arange(deviation.shape[1])
    after = np.where((steps[None] >= first_step[:, None])[..., None], deviation, 0.0)
    return after.max(axis=(1, 2)) > k
