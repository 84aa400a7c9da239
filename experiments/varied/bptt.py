"""The tPC network's online recall, unrolled in torch autograd, and its training by backpropagation
through time. A diagnostic measurement beyond the paper, never a product model.

Same generative model and energy as ``models.tpc.TemporalPC``,

    F = ||z - W_H f(zhat_prev) [- W_C c]||^2 + ||Pi^1/2 (x - W_F f(z))||^2,

and the same test-time inference as the served online recall (``models.recall``, cue of one
step, zero initial state): the prior W_H f(zhat) [+ W_C c] predicts x_t as W_F f(prior), then z
relaxes towards x_t by the chord Gauss-Newton steps of ``models.kernels.gauss_newton`` (step
halving included) and becomes the next zhat. Written in torch, that relaxation is
differentiable, so the one-step error of the observation can be propagated back through every
earlier relaxation and prior to W_H, W_F (and W_C): what the Hebbian rule (eqs. 3-4), which
only sees the current step's errors, cannot do. The trained weights are then loaded into a
``TemporalPC`` and served by the project's own numpy/numba code: this module only trains.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import torch

from neural_asm.models.kernels import MAX_HALVINGS
from neural_asm.models.tpc import TemporalPC


@dataclass(frozen=True)
class BPTTConfig:
    """How the weights are fitted; the model's form is the TemporalPC's (its TPCConfig)."""

    # Chosen on the precision split (observed context, seed 0): 120 epochs at 2e-3 without noise
    # reached a one-step error of 0.3236 there, 150 epochs with the robust preset's noise 0.3222.
    epochs: int = 150
    learning_rate: float = 2e-3
    lr_final_fraction: float = 0.01  # cosine decay, as models.train.learning_rate
    batch_size: int = 40  # sequences per update (demonstrations are shuffled every epoch)
    training_noise: float = 0.35  # std of Gaussian noise on the observations the relaxations see (as ROBUST)
    clip_norm: float = 1.0  # gradient norm clipping: long unrolls can spike
    eval_every: int = 10  # epochs between validation errors (the kept epoch is the best one)
    # Observation channels the loss (and the kept epoch's validation error) counts; empty: all of
    # them, the benchmark's held-out error. A probe: can the form fit the joints alone?
    loss_channels: tuple[int, ...] = ()
    seed: int = 0


def energy(z: torch.Tensor, prior: torch.Tensor, x: torch.Tensor, w_f: torch.Tensor, scale: torch.Tensor) -> torch.Tensor:
    """F per row (B,): ||z - prior||^2 + ||scale * (x - W_F f(z))||^2 with scale = Pi^1/2."""
    residual = (x - torch.tanh(z) @ w_f.T) * scale
    return ((z - prior) ** 2).sum(-1) + (residual**2).sum(-1)


def relax(prior: torch.Tensor, x: torch.Tensor, w_f: torch.Tensor, scale: torch.Tensor, steps: int) -> torch.Tensor:
    """z after ``steps`` chord Gauss-Newton steps on F from the prior: ``models.kernels.gauss_newton``
    in batched torch, differentiable in prior, x and W_F.

    The curvature I + J^T J, J = Pi^1/2 W_F diag(f'(prior)), is factored once at the prior and
    solved in observation space (Woodbury); a step that would raise F is halved up to
    MAX_HALVINGS times, and a row whose F still rises keeps its z. Which halving a row accepts is
    chosen without gradient: piecewise, so autograd differentiates the branch taken.
    """
    w = w_f * scale[:, None]
    target = x * scale
    size = w.shape[0]
    slope = 1 - torch.tanh(prior) ** 2  # J = w diag(slope), applied as products with w
    # J J^T = w diag(slope^2) w^T for every row at once: one product with the (D*D, H) outer products of w's rows.
    gram = ((slope**2) @ (w[:, None, :] * w[None, :, :]).reshape(size * size, -1).T).reshape(-1, size, size)
    factor = torch.linalg.cholesky(torch.eye(size, dtype=w.dtype) + gram)
    z = prior
    current = energy(z, prior, x, w_f, scale)
    fractions = torch.tensor([0.5**h for h in range(MAX_HALVINGS + 1)], dtype=w.dtype)
    for _ in range(steps):
        fz = torch.tanh(z)
        residual = target - fz @ w.T
        grad = (z - prior) - (1 - fz**2) * (residual @ w)
        solution = torch.cholesky_solve(((slope * grad) @ w.T)[..., None], factor)[..., 0]  # (I + J J^T)^-1 J g
        dz = grad - slope * (solution @ w)
        with torch.no_grad():  # which halving each row accepts: a choice, not a quantity to differentiate
            candidates = z[:, None] - fractions[None, :, None] * dz[:, None]  # (B, halvings, H)
            trial = energy(candidates, prior[:, None], x[:, None], w_f, scale)  # (B, halvings)
            accepted = trial <= current[:, None]
            keep = ~accepted.any(1)
            index = accepted.to(torch.uint8).argmax(1)
            current = torch.where(keep, current, trial[torch.arange(len(z)), index])
        z = torch.where(keep[:, None], z, z - fractions[index][:, None] * dz)
    return z


@dataclass
class Weights:
    """The learnable tensors of a TemporalPC, as torch leaves, and what stays fixed."""

    w_h: torch.Tensor
    w_f: torch.Tensor
    w_c: torch.Tensor | None
    scale: torch.Tensor  # Pi^1/2, fixed (estimated from the demonstrations, as the product does)
    context_index: tuple[int, ...]
    steps: int  # Gauss-Newton steps of the relaxation
    wf_max_norm: float

    @classmethod
    def of(cls, net: TemporalPC, dtype: torch.dtype = torch.float32) -> "Weights":
        if net.config.solver != "gauss_newton" or net.config.initial_state != "zeros":
            raise ValueError("the unrolled recall mirrors the Gauss-Newton relaxation from a zero initial state")
        w_c = net.W_C.to(dtype).clone().requires_grad_(True) if net.has_context else None
        return cls(net.W_H.to(dtype).clone().requires_grad_(True), net.W_F.to(dtype).clone().requires_grad_(True),
                   w_c, torch.from_numpy(net.pi_sqrt.copy()).to(dtype), net.context_index,
                   net.config.solver_iterations, net.wf_max_norm)

    @property
    def parameters(self) -> list[torch.Tensor]:
        return [self.w_h, self.w_f] + ([] if self.w_c is None else [self.w_c])

    def load_into(self, net: TemporalPC) -> None:
        """Give the trained weights to the project's network (precision unchanged)."""
        net.load_weights(self.w_h.detach().float(), self.w_f.detach().float(),
                         W_C=None if self.w_c is None else self.w_c.detach().float())

    @torch.no_grad()
    def project(self) -> None:
        """||W_F||_2 <= wf_max_norm, the constraint the product's training keeps (TemporalPC.project)."""
        norm = torch.linalg.matrix_norm(self.w_f, ord=2)
        if norm > self.wf_max_norm:
            self.w_f.mul_(self.wf_max_norm / norm)


def online_expectations(weights: Weights, x: torch.Tensor, seen: torch.Tensor | None = None) -> torch.Tensor:
    """(N, T, D) what online recall cued by one step expects of each step of x (N, T, D):
    step 0 its reconstruction, step t >= 1 W_F f(W_H f(z_{t-1}) [+ W_C c]), as ``models.recall.run``.

    ``seen`` (default x) is what the relaxations are given, e.g. x plus training noise.
    """
    seen = x if seen is None else seen
    n, steps, _ = x.shape
    context = seen[:, 0, list(weights.context_index)] if weights.w_c is not None else None
    push = torch.zeros(n, weights.w_h.shape[0], dtype=x.dtype) if context is None else context @ weights.w_c.T
    prior = push  # W_H f(0) = 0
    out, z = [], None
    for t in range(steps):
        if t > 0:
            prior = torch.tanh(z) @ weights.w_h.T + push
        z = relax(prior, seen[:, t], weights.w_f, weights.scale, weights.steps)
        out.append(torch.tanh(z if t == 0 else prior) @ weights.w_f.T)
    return torch.stack(out, dim=1)


def one_step_loss(weights: Weights, x: torch.Tensor, seen: torch.Tensor | None = None,
                  channels: tuple[int, ...] = ()) -> torch.Tensor:
    """Mean squared one-step error after the first step: the benchmark's held-out error (over
    ``channels`` only, if given)."""
    error = (x[:, 1:] - online_expectations(weights, x, seen)[:, 1:]) ** 2
    return (error[..., list(channels)] if channels else error).mean()


def train_bptt(net: TemporalPC, sequences: np.ndarray, validation: np.ndarray, config: BPTTConfig,
               log: list[dict] | None = None) -> int:
    """Fit the network's weights to normalised sequences (N, T, D) by BPTT through the unrolled
    online recall (Adam, cosine-decayed rate), keeping the evaluated epoch with the lowest
    one-step error on the normalised ``validation`` sequences; loads them into ``net`` and
    returns that epoch (0-based). ``log`` collects {epoch, train, validation} rows."""
    torch.manual_seed(config.seed)
    rng = np.random.default_rng(config.seed)
    weights = Weights.of(net)
    optim = torch.optim.Adam(weights.parameters, lr=config.learning_rate)
    floor = config.lr_final_fraction
    sched = torch.optim.lr_scheduler.LambdaLR(
        optim, lambda e: floor + (1 - floor) * (1 + math.cos(math.pi * e / config.epochs)) / 2)
    data, held_out = torch.from_numpy(np.ascontiguousarray(sequences, np.float32)), torch.from_numpy(
        np.ascontiguousarray(validation, np.float32))
    best: tuple[float, int, list[torch.Tensor]] = (math.inf, -1, [p.detach().clone() for p in weights.parameters])
    for epoch in range(config.epochs):
        order = rng.permutation(len(data))
        total = 0.0
        for start in range(0, len(data), config.batch_size):
            x = data[order[start:start + config.batch_size]]
            seen = x + config.training_noise * torch.randn_like(x) if config.training_noise > 0 else x
            loss = one_step_loss(weights, x, seen, config.loss_channels)
            optim.zero_grad()
            loss.backward()
            torch.nn.utils.clip_grad_norm_(weights.parameters, config.clip_norm)
            optim.step()
            weights.project()
            total += float(loss.detach()) * len(x)
        sched.step()
        if not math.isfinite(total):
            raise FloatingPointError(f"BPTT loss became {total} at epoch {epoch}")
        if (epoch + 1) % config.eval_every == 0 or epoch + 1 == config.epochs:
            with torch.no_grad():
                error = float(one_step_loss(weights, held_out, channels=config.loss_channels))
            if log is not None:
                log.append({"epoch": epoch, "train": total / len(data), "validation": error})
            if error < best[0]:
                best = (error, epoch, [p.detach().clone() for p in weights.parameters])
    with torch.no_grad():
        for p, kept in zip(weights.parameters, best[2]):
            p.copy_(kept)
    weights.load_into(net)
    return best[1]
