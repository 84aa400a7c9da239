"""One training run per task, as a plain function of picklable arguments, so that a
spawned worker process can run it."""

from __future__ import annotations

import os

os.environ.setdefault("OMP_NUM_THREADS", "1")

from typing import Any  # noqa: E402

import numpy as np  # noqa: E402
import torch  # noqa: E402

from experiments.contextual.config import SKILLS, ContextualConfig  # noqa: E402
from experiments.contextual.dataset import HAND_CHANNELS, conditions_data  # noqa: E402
from experiments.contextual.learners import fit  # noqa: E402
from experiments.contextual.metrics import pead, recall_error  # noqa: E402
from models.config import TPCConfig  # noqa: E402


def init_worker() -> None:
    torch.set_num_threads(1)


def per_cue(values: np.ndarray, labels: np.ndarray) -> dict[str, Any]:
    """Mean over each cue's trials, keyed by the skill's name."""
    return {SKILLS[k].name: values[labels == k].mean(axis=0).tolist() for k in np.unique(labels)}


def separation_task(
    seed: int, condition: str, model: str, cfg: ContextualConfig, tpc: TPCConfig
) -> dict[str, Any]:
    """Train one model on one participant's demonstrations of one condition and recall
    the 24 test trials from their first step."""
    init_worker()
    train = conditions_data(seed, cfg, False)[condition]
    test = conditions_data(seed, cfg, True)[condition]
    fitted = fit(model, train, test, tpc.with_(seed=seed), cfg.inference_sweep)
    motor = train.motor
    mean, std = fitted.normaliser.mean[motor], fitted.normaliser.std[motor]
    hand = (fitted.recalled * std + mean)[..., : len(HAND_CHANNELS)]
    truth = fitted.normaliser.normalise(test.sequences)[..., motor]
    return {
        "seed": seed, "condition": condition, "model": model,
        "pead": per_cue(pead(hand, cfg), test.skills),
        "demo_pead": per_cue(pead(test.hand, cfg), test.skills),
        "hand_path": per_cue(hand, test.skills),
        "recall_error": recall_error(fitted.recalled, truth),
        "error_by_iterations": {k: recall_error(r, truth) for k, r in fitted.by_iterations.items()},
        "history": fitted.history,
    }


def skills_task(seed: int, n_skills: int, cfg: ContextualConfig, tpc: TPCConfig) -> dict[str, Any]:
    """Energy per epoch of a Neural ASM learning n_skills skills (plan-and-execute data,
    the same number of demonstrations and the same channels whatever n_skills)."""
    init_worker()
    train = conditions_data(seed, cfg, False, n_skills, cfg.max_skills)["plan_and_execute"]
    fitted = fit("neural_asm", train, train, tpc.with_(seed=seed))
    return {"seed": seed, "n_skills": n_skills, "history": fitted.history}
