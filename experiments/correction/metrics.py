"""What one run of the correction experiment measured: deviation, recovery, detection.

Deviation is max over joints of |q - q_plan| at 40 Hz (degrees), q_plan the executed plan
(the recalled plan anchored to the scene by `sim.control.anchor_plan`) interpolated as the controller does.
"""

from __future__ import annotations

import numpy as np

from neural_asm.experiments.correction.config import CorrectionConfig
from neural_asm.sim.config import SIM
from neural_asm.sim.episode import Episode


def reference_hi(plan: np.ndarray, t_hi: np.ndarray) -> np.ndarray:
    """The 2 Hz joint plan interpolated at the 40 Hz trace times, as the controller does."""
    steps = np.arange(len(plan)) / SIM.timing.observation_hz
    return np.stack([np.interp(t_hi, steps, plan[:, j]) for j in range(plan.shape[1])], axis=1)


def deviation_deg(episode: Episode) -> np.ndarray:
    """(301,) max_j |q_j - q_plan,j| in degrees."""
    return np.degrees(np.abs(episode.qpos_hi - reference_hi(episode.plan, episode.t_hi))).max(axis=1)


def run_metrics(episode: Episode, config: CorrectionConfig) -> dict:
    """Peak and late deviation, cube placement and recovery of one run."""
    dev, t = deviation_deg(episode), episode.t_hi
    late = float(dev[t >= config.deadline_s - 1e-9].max())
    return {
        "peak_dev_deg": float(dev[t >= config.hit.release_s].max()),
        "late_dev_deg": late,
        "cube_error_m": float(episode.cube_error_m),
        "placed": bool(episode.success),
        "recovered": bool(episode.success and late < config.band_deg),
    }


def first_hit_step(config: CorrectionConfig) -> int:
    """The first observation (at the config's rate) that can see the hit: observations are taken
    before their ticks (9 at 2 Hz, 161 at 40 Hz for a release at 4 s)."""
    return int(np.floor(config.hit.release_s * config.rate + 1e-9)) + 1


def detection(energies: np.ndarray, threshold: float, config: CorrectionConfig) -> dict:
    """Did the monitor flag the hit: the first step from the hit on whose energy exceeds the threshold."""
    first = first_hit_step(config)
    after = energies[first:]
    above = np.flatnonzero(after > threshold)
    return {
        "detected": bool(above.size),
        "detect_step": int(first + above[0]) if above.size else None,
        "peak_energy": float(after.max()),
        "threshold": float(threshold),
        "flagged_before_hit": bool((energies[:first] > threshold).any()),
    }
