"""The temporal predictive coding network of the paper (Methods, eqs. 1-6).

The energy at step mu is (eq. 1)

    F = ||z - W_H f(zhat_prev) - W_C c||^2 + ||x - W_F f(z)||^2,   f = tanh, no biases.

W_C c is optional: the tPC with inputs of the temporal predictive coding literature, where c is
what the episode's first observation says of its context (cube pose, goal, obstacle). Without
context channels the term is absent and the energy is the paper's.

So are direct pathways (beyond the paper): with ``config.direct_lags`` = L > 0 the last L
observations p = [x_{t-1}, ..., x_{t-L}] (the first standing in for the steps before it) enter
the prediction through W_D, where ``config.direct_target`` says:
- "observation": x is expected as W_F f(z) + W_D p. The hidden state only has to carry what the
  recent past does not say, and W_D learns by W_F's local rule, (Pi eps_x) p^T. With W_F = 0
  this is a linear model of the last L steps.
- "hidden": the prior becomes W_H f(zhat) (+ W_C c) + W_D p, the tPC with inputs fed the recent
  observations, and W_D learns by W_H's rule, eps_z p^T. The recent past then shapes the next
  state through the network's nonlinearity, together with what the state knows of skill and phase.
With W_D = 0 (where training starts) the network is the paper's.

torch holds the parameters (what checkpoints store). The relaxation of z (eq. 2) and the
learning (models/train.py) run on numpy views of the same memory: they are loops of tiny
operations (K=100 gradient steps, or two Gauss-Newton steps, and Adam, compiled in
models/kernels.py), where torch's per-call overhead would cost more than the arithmetic,
and no autograd is needed because the learning rules (eqs. 3-4) are local Hebbian products
written out below.
"""

from __future__ import annotations

import math

import numpy as np
import torch

from neural_asm.models.config import TPCConfig
from neural_asm.models.kernels import gauss_newton, spectral_norm


def stable_wf_norm(inference_rate: float, margin: float = 0.5) -> float:
    """Largest ||W_F||_2 for which the relaxation of eq. 2 cannot diverge.

    Gradient descent on F in z is stable while gamma < 2 / lambda_max of its Hessian,
    I + D W_F^T W_F D with D = diag(f'(z)), |f'| <= 1. So lambda_max <= 1 + ||W_F||^2,
    and ||W_F||^2 < 2/gamma - 1 suffices; ``margin`` keeps us well inside that bound.
    """
    return math.sqrt(margin * (2.0 / inference_rate - 1.0))


def relative_precision(spread: np.ndarray, floor: float = 0.05) -> np.ndarray:
    """Channel precisions from their spreads (D,), relative to the median channel: channels
    steadier than the median get 1, noisier ones (median / spread)^2, down to ``floor``. Kept
    in (0, 1] so that the bound on W_F that keeps inference stable holds whatever they are."""
    spread = np.asarray(spread, np.float64)
    return np.clip((np.median(spread) / np.maximum(spread, 1e-9)) ** 2, floor, 1.0)


class TemporalPC:
    """Weights W_H (H x H), W_F (D x H), optionally W_C (H x C) and W_D (D or H x L*D), and the
    inference and learning rules.

    ``context_index`` names the observation channels whose values at the first step are the
    context input c of every later prior (empty: the paper's network, no W_C).
    """

    def __init__(self, obs_size: int, config: TPCConfig, context_index: tuple[int, ...] = ()) -> None:
        self.config = config
        self.obs_size = obs_size
        self.context_index = tuple(int(i) for i in context_index)
        if any(not 0 <= i < obs_size for i in self.context_index) or len(set(self.context_index)) != len(self.context_index):
            raise ValueError(f"context_index must be distinct channels in [0, {obs_size}), got {context_index!r}")
        h = config.hidden_size
        gen = torch.Generator().manual_seed(config.seed)
        # nn.Linear's Kaiming-uniform initialisation, U(+-1/sqrt(fan_in)), as the paper says.
        bound = 1.0 / math.sqrt(h)
        self.W_H = (torch.rand(h, h, generator=gen) * 2 - 1) * bound
        self.W_F = (torch.rand(obs_size, h, generator=gen) * 2 - 1) * bound
        n_context = len(self.context_index)
        self.W_C = (torch.rand(h, n_context, generator=gen) * 2 - 1) / math.sqrt(max(n_context, 1))
        # Where W_D p goes, read on every step: into the expected observation or the hidden prior.
        self.direct_x = self.has_direct and config.direct_target == "observation"
        self.direct_z = self.has_direct and config.direct_target == "hidden"
        # Zero: training starts from the paper's network and the local rule grows the pathways
        # (unless config.direct_init says to start them from least squares: fit_direct).
        self.W_D = torch.zeros(h if config.direct_target == "hidden" else obs_size, obs_size * config.direct_lags)
        # Precision of each observation channel in the energy, ||x - W_F f(z)||^2_Pi.
        # All ones is the paper's model; values are kept in (0, 1] so the stability
        # bound on W_F (stable_wf_norm) is unchanged.
        self.precision = torch.ones(obs_size)
        self._bind_views()

    def _bind_views(self) -> None:
        self.w_h = self.W_H.numpy()
        self.w_f = self.W_F.numpy()
        self.w_c = self.W_C.numpy()
        self.w_d = self.W_D.numpy()
        self.pi = self.precision.numpy()
        self.pi_sqrt = np.sqrt(self.pi)

    @property
    def has_context(self) -> bool:
        return bool(self.context_index)

    @property
    def has_direct(self) -> bool:
        return self.config.direct_lags > 0

    @property
    def parameters(self) -> list[torch.Tensor]:
        """The weights that learn: W_H, W_F, W_C with context channels, W_D with direct pathways."""
        weights = [self.W_H, self.W_F]
        if self.has_context:
            weights.append(self.W_C)
        if self.has_direct:
            weights.append(self.W_D)
        return weights

    def initial_past(self, x: np.ndarray) -> np.ndarray | None:
        """The direct pathways' input p at step 0 of observations x (B, D): x standing in for
        every step before it, as a delay embedding does (None without direct pathways)."""
        return np.tile(x, (1, self.config.direct_lags)).astype(np.float32) if self.has_direct else None

    @staticmethod
    def push(past: np.ndarray | None, x: np.ndarray) -> np.ndarray | None:
        """p for the next step: x in front, the oldest step dropped."""
        return None if past is None else np.concatenate([x, past[:, : past.shape[1] - x.shape[1]]], axis=1, dtype=past.dtype)

    def fit_direct(self, sequences: np.ndarray) -> None:
        """W_D into the observation set to the ridge regression of every step of normalised
        sequences (N, T, D) on its past p, as recall builds p (``initial_past``, ``push``)."""
        if not self.direct_x:
            raise ValueError("fit_direct sets pathways into the observation; this network has none")
        past = self.initial_past(sequences[:, 0])
        pasts = []
        for t in range(sequences.shape[1]):
            pasts.append(past)
            past = self.push(past, sequences[:, t])
        p = np.concatenate(pasts).astype(np.float64)
        y = sequences.transpose(1, 0, 2).reshape(-1, self.obs_size).astype(np.float64)
        gram = p.T @ p
        ridge = self.config.direct_ridge * np.trace(gram) / len(gram)
        self.w_d[:] = np.linalg.solve(gram + ridge * np.eye(len(gram)), p.T @ y).T

    def context_of(self, x: np.ndarray) -> np.ndarray | None:
        """The context input c of a (normalised) observation batch (B, D), or None without W_C."""
        return np.ascontiguousarray(x[:, self.context_index]) if self.has_context else None

    def set_precision(self, precision: np.ndarray) -> None:
        precision = np.asarray(precision, np.float32)
        if precision.shape != (self.obs_size,) or not ((precision > 0) & (precision <= 1)).all():
            raise ValueError(f"precision must be {self.obs_size} values in (0, 1], got {precision!r}")
        self.precision = torch.from_numpy(precision.copy())
        self._bind_views()

    def load_weights(self, W_H: torch.Tensor, W_F: torch.Tensor, precision: torch.Tensor | None = None,
                     W_C: torch.Tensor | None = None, W_D: torch.Tensor | None = None) -> None:
        h = self.config.hidden_size
        if tuple(W_H.shape) != (h, h) or tuple(W_F.shape) != (self.obs_size, h):
            raise ValueError(
                f"weight shapes W_H {tuple(W_H.shape)}, W_F {tuple(W_F.shape)} do not match "
                f"hidden_size={h}, obs_size={self.obs_size}"
            )
        n_context = len(self.context_index)
        if (W_C is None) != (n_context == 0) or (W_C is not None and tuple(W_C.shape) != (h, n_context)):
            got = None if W_C is None else tuple(W_C.shape)
            raise ValueError(f"W_C {got} does not match {n_context} context channels and hidden_size={h}")
        direct = tuple(self.W_D.shape)
        if (W_D is None) != (not self.has_direct) or (W_D is not None and tuple(W_D.shape) != direct):
            got = None if W_D is None else tuple(W_D.shape)
            raise ValueError(f"W_D {got} does not match direct_lags={self.config.direct_lags}: expected "
                             f"{direct if self.has_direct else None}")
        self.W_H = W_H.detach().to(torch.float32).contiguous().clone()
        self.W_F = W_F.detach().to(torch.float32).contiguous().clone()
        if W_C is not None:
            self.W_C = W_C.detach().to(torch.float32).contiguous().clone()
        if W_D is not None:
            self.W_D = W_D.detach().to(torch.float32).contiguous().clone()
        self._bind_views()
        if precision is not None:
            self.set_precision(precision.numpy())

    @property
    def wf_max_norm(self) -> float:
        cap = self.config.wf_max_norm
        return stable_wf_norm(self.config.inference_rate) if cap is None else cap

    def initial_state(self, batch: int, rng: np.random.Generator | None = None) -> np.ndarray:
        """zhat before step 0 (see TPCConfig.initial_state); a random one is drawn from
        ``rng``, default_rng(0) if None."""
        h = self.config.hidden_size
        if self.config.initial_state == "zeros":
            return np.zeros((batch, h), np.float32)
        bound = math.sqrt(6.0 / h)
        return (rng or np.random.default_rng(0)).uniform(-bound, bound, (batch, h)).astype(np.float32)

    def context_drive(self, context: np.ndarray | None) -> np.ndarray | None:
        """W_C c, a context input's (B, C) part of the prior (None without one): the same at every
        step of an episode, so recall computes it once (`prior`'s ``drive``)."""
        return None if context is None else context @ self.w_c.T

    def prior(self, zhat_prev: np.ndarray, context: np.ndarray | None = None,
              past: np.ndarray | None = None, *, drive: np.ndarray | None = None,
              hidden_t: np.ndarray | None = None) -> np.ndarray:
        """Temporal prediction of the hidden state, W_H f(zhat_prev) (+ W_C c with a context input,
        + W_D p with direct pathways into the hidden state).

        Recall gives the context's part already multiplied (``drive``, `context_drive`) instead of
        ``context``, and may give W_H^T laid out contiguous (``hidden_t``, `Recaller.lay_out`):
        OpenBLAS multiplies a batch of a few rows by the transposed view W_H.T several times more
        slowly than by a contiguous copy (~60 us against ~10 us for 7 rows of 256)."""
        prior = np.tanh(zhat_prev) @ (self.w_h.T if hidden_t is None else hidden_t)
        drive = self.context_drive(context) if drive is None else drive
        if drive is not None:
            prior += drive
        if self.direct_z:
            prior += past @ self.w_d.T
        return prior

    def observe(self, z: np.ndarray, past: np.ndarray | None = None) -> np.ndarray:
        """Prediction of the observation from a hidden state, W_F f(z) (+ W_D p with direct pathways
        into the observation)."""
        expected = np.tanh(z) @ self.w_f.T
        if self.direct_x:
            expected += past @ self.w_d.T
        return expected

    def infer(self, prior: np.ndarray, x: np.ndarray, steps: int | None = None,
              past: np.ndarray | None = None) -> np.ndarray:
        """Relax z from the prior towards the observation x: the minimum of F in z (eq. 2).

        ``config.solver`` chooses how: the paper's fixed K steps of gradient descent, or a few
        Gauss-Newton steps, which reach the same minimum far sooner. ``steps`` overrides K or
        the number of Gauss-Newton steps. W_D p does not depend on z: with direct pathways
        into the observation z relaxes towards what they leave of x.
        """
        if self.direct_x:
            x = x - past @ self.w_d.T
        if self.config.solver == "gauss_newton":
            return self._gauss_newton(prior, x, self.config.solver_iterations if steps is None else steps)
        return self._gradient_descent(prior, x, self.config.inference_steps if steps is None else steps)

    def _gradient_descent(self, prior: np.ndarray, x: np.ndarray, steps: int) -> np.ndarray:
        """K fixed steps of eq. 2, as in the paper (whose Pi is the identity):

        z <- z + gamma * (-eps_z + f'(z) * ((Pi eps_x) @ W_F)),
        eps_z = z - prior, eps_x = x - W_F f(z).
        """
        gamma = np.float32(self.config.inference_rate)
        keep = np.float32(1.0) - gamma
        # Pi and gamma folded into W_F once; W_F^T made contiguous for the first product.
        w_f_step, w_ft = (gamma * self.pi[:, None]) * self.w_f, np.ascontiguousarray(self.w_f.T)
        z = prior.copy()
        gamma_prior = gamma * prior
        for _ in range(steps):
            fz = np.tanh(z)
            drive = (x - fz @ w_ft) @ w_f_step  # gamma (Pi eps_x) W_F
            fz *= fz
            fz -= 1.0  # -f'(z)
            drive *= fz
            # z - gamma * (z - prior) + gamma * f'(z) * ((Pi eps_x) @ W_F), in place.
            z *= keep
            z += gamma_prior
            z -= drive
        return z

    def _gauss_newton(self, prior: np.ndarray, x: np.ndarray, steps: int) -> np.ndarray:
        """Gauss-Newton steps on F in z, each solved in the observation space.

        With J = Pi^1/2 W_F D, D = diag(f'(z)), half the gradient of F is
        g = (z - prior) - J^T Pi^1/2 eps_x and its Gauss-Newton curvature is I + J^T J:
        the identity (the prior) plus a rank-D term (the observation). By the Woodbury
        identity (I + J^T J)^-1 g = g - J^T (I_D + J J^T)^-1 J g: one D x D system per
        sequence instead of an H x H one. The curvature drops only the tanh'' term, which
        vanishes with the error, so near the minimum the steps converge at once. It is
        evaluated and factored once, at the prior, and kept for the later steps (the chord
        method): building it costs more than the rest of a step, and on the paper's task
        two steps leave ~5e-6 of the energy above its minimum either way
        (benchmarks/bench_models.py measures the gap against a z converged to 1e-6).

        Far from what the network can predict (an observation tens of normalised units off)
        tanh saturates and a full step can overshoot: a step that would raise F is halved,
        up to ``models.kernels.MAX_HALVINGS`` times, and a sequence whose F still rises keeps
        its z. F never increases.
        """
        return gauss_newton(np.ascontiguousarray(prior, np.float32), np.ascontiguousarray(x, np.float32),
                            self.w_f, self.pi_sqrt, steps)

    def hebbian_terms(
        self, zhat_prev: np.ndarray, prior: np.ndarray, z: np.ndarray, x: np.ndarray,
        context: np.ndarray | None = None, past: np.ndarray | None = None,
    ) -> tuple[list[tuple[np.ndarray, np.ndarray]], float]:
        """The Hebbian terms of eqs. 3-4 as (postsynaptic error, presynaptic activity) pairs, one
        per weight in the order of ``parameters``, and the batch's mean energy F.

        A weight (O, I) learns from its pair (post (B, O), pre (B, I)) by post^T pre / B, the
        negative gradient of F averaged over the batch: eps_z f(zhat_prev)^T for W_H,
        (Pi eps_x) f(z)^T for W_F, like W_H eps_z c^T for W_C and, for W_D, (Pi eps_x) p^T into the
        observation like W_F, eps_z p^T into the hidden state like W_H. The products are left to
        the update (``models.train.WeightUpdate``), which forms them in buffers it keeps.
        """
        fz = np.tanh(z)
        eps_z = z - prior
        eps_x = x - self.observe(z, past)
        weighted = eps_x * self.pi
        terms = [(eps_z, np.tanh(zhat_prev)), (weighted, fz)]
        if self.has_context:
            terms.append((eps_z, context))
        if self.has_direct:
            terms.append((weighted if self.direct_x else eps_z, past))
        energy = float((eps_z * eps_z).sum() + (weighted * eps_x).sum()) / x.shape[0]
        return terms, energy

    def project(self) -> None:
        """Keep ||W_F||_2 <= wf_max_norm so that inference stays stable (see stable_wf_norm)."""
        cap = self.wf_max_norm
        if float(np.linalg.norm(self.w_f)) <= cap:  # Frobenius >= spectral: nothing to do
            return
        norm = spectral_norm(self.w_f)
        if norm > cap:
            self.w_f *= np.float32(cap / norm)
