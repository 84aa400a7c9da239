"""Recurrent baselines trained with BPTT on the demonstrations (torch, one CPU thread).

- ``GRUOneStep``: a GRU reads x[0..t] (with the skill as a one-hot input) and predicts
  x[t+1] as x[t] plus a learned change; trained with teacher forcing, i.e. exactly as it
  runs online.
- ``LSTMVAE``: the LSTM-VAE reconstruction detector of Park, Hoshi & Kemp (2018, RA-L),
  made causal: an LSTM encoder over x[0..t] gives q(z_t | x[0..t]); an LSTM decoder over
  z[0..t] gives a Gaussian over x_t, whose mean is what the detector expects. The prior
  of z_t is N(mu(t), I) with a learned mean per step (Park et al.'s progress-based prior).
  Trained on the ELBO with the KL weight annealed from 0 to 1. PyOD (checked at 2.x) has a
  dense VAE and an LSTM forecaster but no LSTM-VAE, so it is written here.

Both stop early on the best loss of a held-out 20 % of the demonstrations (every skill
represented) and are deterministic given the seed.
"""

from __future__ import annotations

import copy
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass

import numpy as np
import torch
from torch import nn

from neural_asm.rivals.base import DetectorBase

Tensor = torch.Tensor


@dataclass(frozen=True)
class RecurrentConfig:
    """Training of the recurrent baselines; defaults fit 160 demonstrations in well under a minute."""

    hidden_size: int = 128
    latent_size: int = 8  # LSTM-VAE only
    learning_rate: float = 3e-3
    batch_size: int = 32
    max_epochs: int = 400
    patience: int = 30  # epochs without a better held-out loss before stopping
    kl_anneal_epochs: int = 40  # LSTM-VAE only: KL weight rises linearly to 1 over these
    held_out: float = 0.2


@contextmanager
def _torch_session(seed: int) -> Iterator[None]:
    """A private random stream, the caller's restored afterwards."""
    with torch.random.fork_rng(devices=[]):
        torch.manual_seed(seed)
        yield


def _held_out_split(skills: np.ndarray, fraction: float, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Train and held-out indices, at least one held-out demonstration per skill."""
    rng = np.random.default_rng(seed)
    held: list[int] = []
    for s in np.unique(skills):
        rows = rng.permutation(np.flatnonzero(skills == s))
        held.extend(rows[: max(1, round(fraction * len(rows)))].tolist())
    mask = np.zeros(len(skills), bool)
    mask[held] = True
    return np.flatnonzero(~mask), np.flatnonzero(mask)


class RecurrentDetector(DetectorBase):
    """Shared training loop; subclasses build the network and define its loss and expectation."""

    def __init__(self, config: RecurrentConfig | None = None) -> None:
        super().__init__()
        self.config = config or RecurrentConfig()
        self.epochs_run = 0

    def _one_hot(self, skills: np.ndarray) -> Tensor:
        index = np.searchsorted(self.skill_names, skills)
        return torch.as_tensor(np.eye(len(self.skill_names), dtype=np.float32)[index])

    def _build(self) -> nn.Module:
        raise NotImplementedError

    def _loss(self, x: Tensor, onehot: Tensor, epoch: int, train: bool) -> Tensor:
        raise NotImplementedError

    def _fit(self, x: np.ndarray, skills: np.ndarray, seed: int) -> None:
        cfg = self.config
        train, held = _held_out_split(skills, cfg.held_out, seed)
        data = torch.as_tensor(x, dtype=torch.float32)
        onehot = self._one_hot(skills)
        rng = np.random.default_rng(seed)
        with _torch_session(seed):
            self.net = self._build()
            optimizer = torch.optim.Adam(self.net.parameters(), lr=cfg.learning_rate)
            best, best_state, stale = np.inf, copy.deepcopy(self.net.state_dict()), 0
            for epoch in range(cfg.max_epochs):
                self.net.train()
                order = train[rng.permutation(len(train))]
                for start in range(0, len(order), cfg.batch_size):
                    idx = torch.as_tensor(order[start : start + cfg.batch_size])
                    loss = self._loss(data[idx], onehot[idx], epoch, train=True)
                    optimizer.zero_grad()
                    loss.backward()
                    nn.utils.clip_grad_norm_(self.net.parameters(), 1.0)
                    optimizer.step()
                self.net.eval()
                with torch.no_grad():
                    held_loss = self._loss(data[held], onehot[held], epoch, train=False).item()
                self.epochs_run = epoch + 1
                if not self._tracking(epoch):
                    continue
                if held_loss < best:
                    best, best_state, stale = held_loss, copy.deepcopy(self.net.state_dict()), 0
                else:
                    stale += 1
                    if stale >= cfg.patience:
                        break
        self.net.load_state_dict(best_state)
        self.net.eval()

    def _tracking(self, epoch: int) -> bool:
        """Whether the held-out loss of this epoch is comparable with later ones."""
        return True

    def _predict(self, forward: Callable[[Tensor, Tensor], Tensor], x: np.ndarray, skills: np.ndarray) -> np.ndarray:
        with _torch_session(0), torch.no_grad():
            return forward(torch.as_tensor(x, dtype=torch.float32), self._one_hot(skills)).double().numpy()


class _GRUPredictor(nn.Module):
    def __init__(self, dims: int, n_skills: int, hidden: int) -> None:
        super().__init__()
        self.gru = nn.GRU(dims + n_skills, hidden, batch_first=True)
        self.readout = nn.Linear(hidden, dims)

    def forward(self, x: Tensor, onehot: Tensor) -> Tensor:
        """Predictions (B, T-1, D) of steps 1..T-1, step t+1 from x[0..t]."""
        inputs = torch.cat([x[:, :-1], onehot[:, None].expand(-1, x.shape[1] - 1, -1)], dim=-1)
        hidden, _ = self.gru(inputs)
        return x[:, :-1] + self.readout(hidden)


class GRUOneStep(RecurrentDetector):
    name = "gru_one_step"
    label = "GRU one-step predictor (BPTT)"

    def _build(self) -> nn.Module:
        return _GRUPredictor(self.dims, len(self.skill_names), self.config.hidden_size)

    def _loss(self, x: Tensor, onehot: Tensor, epoch: int, train: bool) -> Tensor:
        return torch.mean((self.net(x, onehot) - x[:, 1:]) ** 2)

    def _expected(self, x: np.ndarray, skills: np.ndarray) -> np.ndarray:
        if x.shape[1] == 1:
            return x.copy()
        predictions = self._predict(self.net, x, skills)
        return np.concatenate([x[:, :1], predictions], axis=1)


class _LSTMVAENet(nn.Module):
    def __init__(self, dims: int, n_skills: int, steps: int, hidden: int, latent: int) -> None:
        super().__init__()
        self.encoder = nn.LSTM(dims + n_skills, hidden, batch_first=True)
        self.posterior = nn.Linear(hidden, 2 * latent)
        self.prior_mean = nn.Parameter(torch.zeros(steps, latent))
        self.decoder = nn.LSTM(latent + n_skills, hidden, batch_first=True)
        self.readout = nn.Linear(hidden, 2 * dims)

    def forward(self, x: Tensor, onehot: Tensor, sample: bool) -> tuple[Tensor, Tensor, Tensor, Tensor]:
        """Reconstruction mean and log-variance of x (B, T, D), posterior mean and log-variance of z."""
        skill = onehot[:, None].expand(-1, x.shape[1], -1)
        encoded, _ = self.encoder(torch.cat([x, skill], dim=-1))
        z_mean, z_logvar = self.posterior(encoded).chunk(2, dim=-1)
        z = z_mean + torch.exp(0.5 * z_logvar) * torch.randn_like(z_mean) if sample else z_mean
        decoded, _ = self.decoder(torch.cat([z, skill], dim=-1))
        x_mean, x_logvar = self.readout(decoded).chunk(2, dim=-1)
        return x_mean, x_logvar.clamp(-8.0, 8.0), z_mean, z_logvar

    def reconstruct(self, x: Tensor, onehot: Tensor) -> Tensor:
        return self(x, onehot, sample=False)[0]


class LSTMVAE(RecurrentDetector):
    name = "lstm_vae"
    label = "LSTM-VAE reconstruction (Park et al. 2018)"

    def _build(self) -> nn.Module:
        cfg = self.config
        return _LSTMVAENet(self.dims, len(self.skill_names), self.steps, cfg.hidden_size, cfg.latent_size)

    def _kl_weight(self, epoch: int) -> float:
        return min(1.0, (epoch + 1) / self.config.kl_anneal_epochs)

    def _tracking(self, epoch: int) -> bool:
        return self._kl_weight(epoch) >= 1.0

    def _loss(self, x: Tensor, onehot: Tensor, epoch: int, train: bool) -> Tensor:
        """Negative ELBO per step (annealed KL weight in training, full weight held out)."""
        x_mean, x_logvar, z_mean, z_logvar = self.net(x, onehot, sample=train)
        nll = 0.5 * (x_logvar + (x - x_mean) ** 2 / torch.exp(x_logvar)).sum(-1)
        prior = self.net.prior_mean[: x.shape[1]]
        kl = 0.5 * (torch.exp(z_logvar) + (z_mean - prior) ** 2 - 1.0 - z_logvar).sum(-1)
        weight = self._kl_weight(epoch) if train else 1.0
        return (nll + weight * kl).mean()

    def _expected(self, x: np.ndarray, skills: np.ndarray) -> np.ndarray:
        return self._predict(self.net.reconstruct, x, skills)
