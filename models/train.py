"""Memorisation: relax z at every step, then apply the Hebbian updates (eqs. 2-4).

The weights change after every time step, with the converged z becoming zhat for the
next step, as the paper's co-author's reference code does. Adam is the default: plain
SGD at the paper's 1e-4 barely learns in the same number of epochs.
"""

from __future__ import annotations

from typing import Callable

import numpy as np
import torch
from tqdm.auto import tqdm

from models.config import TPCConfig
from models.recall import run
from models.tpc import TemporalPC

EpochCallback = Callable[[int, float], None]


def make_optimizer(net: TemporalPC) -> torch.optim.Optimizer:
    params = net.parameters
    lr = net.config.learning_rate
    if net.config.optimizer == "adam":
        # The fused kernel: one call per step instead of a dozen (half the time on these sizes).
        return torch.optim.Adam(params, lr=lr, fused=True)
    return torch.optim.SGD(params, lr=lr)


def make_schedule(
    optimizer: torch.optim.Optimizer, config: TPCConfig
) -> torch.optim.lr_scheduler.LRScheduler | None:
    """Cosine decay of the learning rate to ``lr_final_fraction`` of it at the last epoch.

    Per-step Adam updates at a rate high enough to learn quickly keep the weights
    oscillating between epochs; annealing lets them settle.
    """
    if config.lr_final_fraction >= 1.0:
        return None
    return torch.optim.lr_scheduler.CosineAnnealingLR(
        optimizer, T_max=config.epochs, eta_min=config.learning_rate * config.lr_final_fraction
    )


def train_epoch(
    net: TemporalPC,
    sequences: np.ndarray,
    optimizer: torch.optim.Optimizer,
    rng: np.random.Generator,
) -> float:
    """One pass over all sequences (N, T, D), normalised; returns mean energy per step."""
    n, steps, _ = sequences.shape
    batch = net.config.batch_size or n
    order = rng.permutation(n)
    total, count = 0.0, 0
    for start in range(0, n, batch):
        x_seq = sequences[order[start : start + batch]]
        if net.config.training_noise > 0:
            x_seq = x_seq + np.float32(net.config.training_noise) * rng.standard_normal(x_seq.shape, np.float32)
        zhat = net.initial_state(len(x_seq), rng)
        context = net.context_of(x_seq[:, 0])
        for t in range(steps):
            x = x_seq[:, t]
            prior = net.prior(zhat, context)
            z = net.infer(prior, x)
            grads, energy = net.hebbian_gradients(zhat, prior, z, x, context)
            for weight, grad in zip(net.parameters, grads):
                weight.grad = torch.from_numpy(grad)
            optimizer.step()
            net.project()
            total += energy
            count += 1
            zhat = z
    return total / count


def recall_error(net: TemporalPC, sequences: np.ndarray) -> float:
    """Mean squared error of offline and online recall after the first step (normalised)."""
    errors = [sequences - run(net, sequences, mode) for mode in ("offline", "online")]
    return float(np.mean([(e[:, 1:] ** 2).mean() for e in errors]))


def _checked(sequences: np.ndarray, width: int, what: str) -> np.ndarray:
    sequences = np.ascontiguousarray(sequences, np.float32)
    if sequences.ndim != 3 or sequences.shape[-1] != width:
        raise ValueError(f"{what} must have shape (N, T, {width}), got {sequences.shape}")
    if not np.isfinite(sequences).all():
        raise ValueError(f"{what} contain NaN or inf")
    return sequences


def train(
    net: TemporalPC,
    sequences: np.ndarray,
    progress: bool = True,
    on_epoch: EpochCallback | None = None,
    validation: np.ndarray | None = None,
    eval_every: int = 25,
) -> tuple[list[float], int]:
    """Train on normalised sequences (N, T, D).

    Returns the mean energy of every epoch and the epoch whose weights are kept: the
    last one, or, given held-out ``validation`` sequences, the evaluated epoch with the
    lowest recall error on them. With ~20 demonstrations the recall error on unseen
    episodes stops improving long before the training energy does.
    """
    sequences = _checked(sequences, net.obs_size, "sequences")
    if validation is not None:
        validation = _checked(validation, net.obs_size, "validation sequences")
    best = (np.inf, net.config.epochs - 1, None)
    rng = np.random.default_rng(net.config.seed)
    optimizer = make_optimizer(net)
    schedule = make_schedule(optimizer, net.config)
    history: list[float] = []
    bar = tqdm(range(net.config.epochs), desc="training", unit="epoch", disable=not progress)
    with torch.no_grad():
        for epoch in bar:
            energy = train_epoch(net, sequences, optimizer, rng)
            if not np.isfinite(energy):
                raise FloatingPointError(f"energy became {energy} at epoch {epoch}")
            history.append(energy)
            if schedule is not None:
                schedule.step()
            if validation is not None and ((epoch + 1) % eval_every == 0 or epoch + 1 == net.config.epochs):
                error = recall_error(net, validation)
                if error < best[0]:
                    best = (error, epoch, [w.clone() for w in net.parameters])
                bar.set_postfix(energy=f"{energy:.4g}", held_out=f"{error:.4g}", refresh=False)
            else:
                bar.set_postfix(energy=f"{energy:.4g}", refresh=False)
            if on_epoch is not None:
                on_epoch(epoch, energy)
    if best[2] is not None:
        for weight, kept in zip(net.parameters, best[2]):
            weight.copy_(kept)
    return history, best[1]
