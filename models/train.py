"""Memorisation: relax z at every step, then apply the Hebbian updates (eqs. 2-4).

The weights change after every time step, with the converged z becoming zhat for the
next step, as the paper's co-author's reference code does. Adam is the default: plain
SGD at the paper's 1e-4 barely learns in the same number of epochs.
"""

from __future__ import annotations

import math
from typing import Callable, Sequence

import numpy as np
from tqdm.auto import tqdm

from neural_asm.models.config import Optimizer, TPCConfig
from neural_asm.models.kernels import adam_step
from neural_asm.models.recall import run
from neural_asm.models.sequences import checked_array
from neural_asm.models.tpc import TemporalPC, relative_precision

EpochCallback = Callable[[int, float], None]


class WeightUpdate:
    """Adam (torch.optim.Adam's rule, betas 0.9 / 0.999, eps 1e-8) or plain SGD on the network's
    weights, in place through their numpy views, from the Hebbian terms of each step.

    The gradients are formed in buffers kept from step to step (a fresh quarter-megabyte
    array for W_H every step cost as much in page faults as its product) and Adam's
    arithmetic runs in one compiled call per weight (``models.kernels.adam_step``):
    torch.optim.Adam gives the same updates, but its Python wrapper cost three times the
    arithmetic at these sizes.
    """

    def __init__(self, weights: Sequence[np.ndarray], optimizer: Optimizer) -> None:
        self.weights = list(weights)
        self.grads = [np.empty_like(w) for w in self.weights]
        # Adam's first and second moments per weight; None: plain SGD keeps no state.
        self.moments = [(np.zeros_like(w), np.zeros_like(w)) if optimizer == "adam" else None for w in self.weights]
        self.steps = 0

    def apply(self, terms: Sequence[tuple[np.ndarray, np.ndarray]], rate: float) -> None:
        """Descend the energy along the Hebbian terms (post, pre) of each weight at ``rate``:
        the gradient of a weight is -post^T pre / B."""
        self.steps += 1
        for weight, grad, (post, pre), moments in zip(self.weights, self.grads, terms, self.moments):
            np.matmul((post * np.float32(-1.0 / len(post))).T, pre, out=grad)
            if moments is None:
                grad *= np.float32(rate)
                weight -= grad
            else:
                adam_step(weight, grad, *moments, rate, self.steps)


def learning_rate(config: TPCConfig, epoch: int) -> float:
    """The learning rate of an epoch (0-based): cosine decay from ``config.learning_rate`` to
    ``lr_final_fraction`` of it at the last epoch (torch's CosineAnnealingLR).

    Per-step Adam updates at a rate high enough to learn quickly keep the weights
    oscillating between epochs; annealing lets them settle.
    """
    floor = config.learning_rate * config.lr_final_fraction
    return floor + (config.learning_rate - floor) * (1 + math.cos(math.pi * epoch / config.epochs)) / 2


def train_epoch(
    net: TemporalPC,
    sequences: np.ndarray,
    update: WeightUpdate,
    rate: float,
    rng: np.random.Generator,
) -> tuple[float, np.ndarray]:
    """One pass over all sequences (N, T, D), normalised; returns the mean energy per step and
    each channel's mean squared error at the relaxed state (D,)."""
    n, steps, width = sequences.shape
    batch = net.config.batch_size or n
    order = rng.permutation(n)
    total, count = 0.0, 0
    weighted_sq, rows = np.zeros(width), 0
    for start in range(0, n, batch):
        x_seq = sequences[order[start : start + batch]]
        if net.config.training_noise > 0:
            x_seq = x_seq + np.float32(net.config.training_noise) * rng.standard_normal(x_seq.shape, np.float32)
        zhat = net.initial_state(len(x_seq), rng)
        context = net.context_of(x_seq[:, 0])
        past = net.initial_past(x_seq[:, 0])
        for t in range(steps):
            x = x_seq[:, t]
            prior = net.prior(zhat, context, past)
            z = net.infer(prior, x, past=past)
            terms, energy = net.hebbian_terms(zhat, prior, z, x, context, past)
            update.apply(terms, rate)
            net.project()
            total += energy
            count += 1
            weighted_sq += (terms[1][0].astype(np.float64) ** 2).sum(axis=0)  # W_F's post: Pi eps_x
            rows += len(x)
            zhat, past = z, net.push(past, x)
    return total / count, weighted_sq / rows / net.pi.astype(np.float64) ** 2


def recall_error(net: TemporalPC, sequences: np.ndarray) -> float:
    """Mean squared error of offline and online recall after the first step (normalised)."""
    errors = [sequences - run(net, sequences, mode) for mode in ("offline", "online")]
    return float(np.mean([(e[:, 1:] ** 2).mean() for e in errors]))


def train(
    net: TemporalPC,
    sequences: np.ndarray,
    progress: bool = True,
    on_epoch: EpochCallback | None = None,
    validation: np.ndarray | None = None,
    eval_every: int = 25,
) -> tuple[list[float], int]:
    """Train on normalised sequences (N, T, D).

    Pathways into the observation configured to start from least squares are fitted first.
    With learned precisions (``config.observation_precision``) each channel's precision is set
    after every epoch to the inverse of its mean squared error at the relaxed states, relative
    to the median channel: the fixed point of the local rule dPi_i ~ 1 - Pi_i eps_i^2 (beyond
    the paper), so that channels the hidden state cannot explain weigh less in what it learns.
    Returns the mean energy of every epoch and the epoch whose weights are kept: the
    last one, or, given held-out ``validation`` sequences, the evaluated epoch with the
    lowest recall error on them. With ~20 demonstrations the recall error on unseen
    episodes stops improving long before the training energy does.
    """
    sequences = checked_array(sequences, "sequences", net.obs_size, np.float32)
    if validation is not None:
        validation = checked_array(validation, "validation sequences", net.obs_size, np.float32)
    if net.config.direct_init == "least_squares":
        net.fit_direct(sequences)
    best = (np.inf, net.config.epochs - 1, None, None)
    rng = np.random.default_rng(net.config.seed)
    # numpy views of the parameters: updated in place, the tensors with them.
    update = WeightUpdate([w.numpy() for w in net.parameters], net.config.optimizer)
    history: list[float] = []
    bar = tqdm(range(net.config.epochs), desc="training", unit="epoch", disable=not progress)
    for epoch in bar:
        energy, channel_mse = train_epoch(net, sequences, update, learning_rate(net.config, epoch), rng)
        if not np.isfinite(energy):
            raise FloatingPointError(f"energy became {energy} at epoch {epoch}")
        if net.config.observation_precision == "learned":
            net.set_precision(relative_precision(np.sqrt(channel_mse)))
        history.append(energy)
        if validation is not None and ((epoch + 1) % eval_every == 0 or epoch + 1 == net.config.epochs):
            error = recall_error(net, validation)
            if error < best[0]:
                best = (error, epoch, [w.copy() for w in update.weights], net.pi.copy())
            bar.set_postfix(energy=f"{energy:.4g}", held_out=f"{error:.4g}", refresh=False)
        else:
            bar.set_postfix(energy=f"{energy:.4g}", refresh=False)
        if on_epoch is not None:
            on_epoch(epoch, energy)
    if best[2] is not None:
        for weight, kept in zip(update.weights, best[2]):
            np.copyto(weight, kept)
        net.set_precision(best[3])
    return history, best[1]
