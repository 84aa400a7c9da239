"""One training run per task, as a plain function of picklable arguments, so that a
spawned worker process can run it."""

from __future__ import annotations



from typing import Any

import numpy as np

from neural_asm.experiments.contextual.config import SKILLS, ContextualConfig
from neural_asm.experiments.contextual.dataset import HAND_CHANNELS, conditions_data, hand, motor_index
from neural_asm.experiments.contextual.learners import fit
from neural_asm.experiments.contextual.metrics import pead, recall_error
from neural_asm.models.config import TPCConfig
from neural_asm.models.normaliser import Normaliser
from neural_asm.models.tpc import TemporalPC
from neural_asm.models.train import train


def per_cue(values: np.ndarray, labels: np.ndarray) -> dict[str, Any]:
    """Mean over each cue's trials, keyed by the skill's name."""
    return {SKILLS[k].name: values[labels == k].mean(axis=0).tolist() for k in np.unique(labels)}


def separation_task(
    seed: int, condition: str, model: str, cfg: ContextualConfig, tpc: TPCConfig
) -> dict[str, Any]:
    """Train one model on one participant's demonstrations of one condition and recall
    the 24 test trials from their first step."""
    train = conditions_data(seed, cfg, False)[condition]
    test = conditions_data(seed, cfg, True)[condition]
    fitted = fit(model, train, test, tpc.with_(seed=seed), cfg.inference_sweep)
    motor = motor_index(train.channel_names)
    mean, std = fitted.normaliser.mean[motor], fitted.normaliser.std[motor]
    recalled_hand = (fitted.recalled * std + mean)[..., : len(HAND_CHANNELS)]
    truth = fitted.normaliser.normalise(test.data)[..., motor]
    return {
        "seed": seed, "condition": condition, "model": model,
        "pead": per_cue(pead(recalled_hand, cfg), test.labels),
        "demo_pead": per_cue(pead(hand(test), cfg), test.labels),
        "hand_path": per_cue(recalled_hand, test.labels),
        "demo_path": per_cue(hand(test), test.labels),
        "recall_error": recall_error(fitted.recalled, truth),
        "error_by_iterations": {k: recall_error(r, truth) for k, r in fitted.by_iterations.items()},
        "history": fitted.history,
    }


def skills_task(seed: int, n_skills: int, cfg: ContextualConfig, tpc: TPCConfig) -> dict[str, Any]:
    """Energy per epoch of a Neural ASM learning n_skills skills from plan-and-execute data.

    Whatever n_skills, the demonstrations are as many, have the same channels and are
    z-scored with the statistics of the max_skills data, so that energies are in the
    same units and only the number of distinct skills differs. Trained without the preset's
    training noise: noise redrawn every epoch puts a floor of its own into the energy this
    compares, which hid the difference between skill counts (1 skill 0.71 +- 0.16 vs 4 skills
    0.53 with noise 0.35, three seeds).
    """
    data = lambda n: conditions_data(seed, cfg, False, n, cfg.max_skills)["plan_and_execute"]  # noqa: E731
    normaliser = Normaliser.fit(data(cfg.max_skills).data)
    sequences = normaliser.normalise(data(n_skills).data)
    net = TemporalPC(sequences.shape[-1], tpc.with_(seed=seed, training_noise=0.0))
    return {"seed": seed, "n_skills": n_skills, "history": train(net, sequences, progress=False)[0]}
