"""Train each of the three models on one condition's demonstrations and recall its
motor plans from the first step of test trials (normalised units throughout)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np
import torch

from neural_asm.experiments.contextual.dataset import motor_index, sensory_index
from neural_asm.models.asm import NeuralASM
from neural_asm.models.config import TPCConfig
from neural_asm.models.normaliser import Normaliser
from neural_asm.models.recall import offline_recall
from neural_asm.models.sequences import Sequences
from neural_asm.rivals.rnn import SensorimotorRNN, SensoryToMotorRNN, roll_out, train_rnn
from neural_asm.models.tpc import TemporalPC


@dataclass
class Fitted:
    normaliser: Normaliser
    recalled: np.ndarray  # (N, T, M) motor channels of the test trials, normalised
    history: list[float]  # energy (tPC) or BPTT loss per epoch
    # Neural ASM only: inference iterations K at the cue -> recalled motor channels.
    by_iterations: dict[int, np.ndarray]


def recall_with_iterations(
    net: TemporalPC, cue: np.ndarray, horizon: int, iterations: int
) -> np.ndarray:
    """Offline recall with K iterations of the paper's gradient descent at the cue, sharing
    the trained weights: the speed-accuracy trade-off is that of gradient descent."""
    probe = TemporalPC(net.obs_size, net.config.with_(solver="gradient", inference_steps=iterations))
    probe.load_weights(net.W_H, net.W_F, net.precision)
    return offline_recall(probe, cue, horizon, np.random.default_rng(net.config.seed))


def fit_neural_asm(
    train: Sequences, test: Sequences, config: TPCConfig, sweep: tuple[int, ...] = ()
) -> Fitted:
    model = NeuralASM.fit(train.data, train.channel_names, config, progress=False)
    x = model.normaliser.normalise(test.data)
    steps, motor = x.shape[1], motor_index(train.channel_names)
    recall = lambda k: recall_with_iterations(model.net, x[:, :1], steps, k)[..., motor]  # noqa: E731
    by_iterations = {k: recall(k) for k in sweep}
    recalled = offline_recall(model.net, x[:, :1], steps, np.random.default_rng(config.seed))[..., motor]
    return Fitted(model.normaliser, recalled, model.history, by_iterations)


def fit_s_to_m(train: Sequences, test: Sequences, config: TPCConfig) -> Fitted:
    """Sensory (cue) at step 0, held -> motor at steps 1..T-1; step 0's motor is observed."""
    normaliser = Normaliser.fit(train.data)
    x, xt = normaliser.normalise(train.data), normaliser.normalise(test.data)
    sensory, motor = sensory_index(train.channel_names), motor_index(train.channel_names)
    torch.manual_seed(config.seed)
    net = SensoryToMotorRNN(len(sensory), len(motor), config.hidden_size)
    history = train_rnn(net, x[:, 0, sensory], x[:, 1:, motor], config)
    predicted = roll_out(net, xt[:, 0, sensory], xt.shape[1] - 1)
    return Fitted(normaliser, np.concatenate([xt[:, :1, motor], predicted], axis=1), history, {})


def fit_sm_to_sm(train: Sequences, test: Sequences, config: TPCConfig) -> Fitted:
    """All channels at step 0 -> all channels at steps 1..T-1, closed loop."""
    normaliser = Normaliser.fit(train.data)
    x, xt = normaliser.normalise(train.data), normaliser.normalise(test.data)
    torch.manual_seed(config.seed)
    net = SensorimotorRNN(x.shape[-1], config.hidden_size)
    history = train_rnn(net, x[:, 0], x[:, 1:], config)
    predicted = roll_out(net, xt[:, 0], xt.shape[1] - 1)
    recalled = np.concatenate([xt[:, :1], predicted], axis=1)
    return Fitted(normaliser, recalled[..., motor_index(train.channel_names)], history, {})


def fit(
    model: str, train: Sequences, test: Sequences, config: TPCConfig,
    sweep: tuple[int, ...] = (),
) -> Fitted:
    """Dispatch on the model's name (config.MODELS); the sweep only applies to the tPC."""
    if model == "neural_asm":
        return fit_neural_asm(train, test, config, sweep)
    baselines: dict[str, Callable[[Sequences, Sequences, TPCConfig], Fitted]] = {
        "s_to_m": fit_s_to_m, "sm_to_sm": fit_sm_to_sm,
    }
    if model not in baselines:
        raise ValueError(f"unknown model {model!r}")
    return baselines[model](train, test, config)
