"""Recall (memory expression): offline and online, one step at a time.

Offline recall infers z from the first ``cue_steps`` observations, then rolls the
hidden state forward with W_H alone: the plan is fixed after the cue. Online recall
infers z from the true observation at every step and predicts the next one.

At every step the network first says what it expects, then sees the observation:
- cue steps: z is inferred from x; the expectation is the reconstruction W_F f(z);
- offline, after the cue: z = W_H f(zhat), expectation W_F f(z), no inference;
- online, after the cue: expectation W_F f(W_H f(zhat)), then z is inferred from x.
The eq. 6 relaxation of x-hat starts at, and stays at, the forward prediction
W_F f(z): with x-hat free that is the minimum of eq. 5 (see relax_observation).
A network with direct pathways adds W_D p to every expectation or every prior, p the last
observations it saw, or, offline past the cue, the last ones it expected.
"""

from __future__ import annotations

from typing import Literal, Sequence

import numpy as np

from neural_asm.models.tpc import TemporalPC

NetworkMode = Literal["offline", "online"]
RecallMode = Literal["offline", "online", "plan"]
NETWORK_MODES: tuple[str, ...] = ("offline", "online")  # the network's own recall
# "plan" reads the network's offline recall out per recognised skill (models/plan.py): only
# networks fitted with a plan memory have it.
RECALL_MODES: tuple[str, ...] = (*NETWORK_MODES, "plan")


def check_recall(mode: str, cue_steps: int, modes: tuple[str, ...] = NETWORK_MODES) -> None:
    if mode not in modes:
        raise ValueError(f"recall mode must be one of {modes}, got {mode!r}")
    if cue_steps < 1:
        raise ValueError(f"cue_steps must be >= 1, got {cue_steps}")


class Recaller:
    """The hidden state of a batch of sequences during recall."""

    def __init__(
        self,
        net: TemporalPC,
        batch: int,
        mode: NetworkMode = "offline",
        cue_steps: int = 1,
        rng: np.random.Generator | None = None,
    ) -> None:
        check_recall(mode, cue_steps)
        self.net, self.mode, self.cue_steps = net, mode, cue_steps
        self.zhat = net.initial_state(batch, rng)
        # W_C c, the part of every prior the context read from the first observation drives
        # (networks with W_C): computed once, at that step.
        self.drive: np.ndarray | None = None
        self.hidden_t: np.ndarray | None = None  # W_H^T laid out contiguous, once `lay_out` has run
        self.past: np.ndarray | None = None  # the direct pathways' input p (networks with W_D)
        # Once ``forecast`` has run: the next step's prior W_H f(zhat) (+ W_C c) and what it
        # predicts, W_F f(prior), which past the cue is that step's expectation.
        self.next_prior: np.ndarray | None = None
        self.next_expected: np.ndarray | None = None
        self.t = 0

    @classmethod
    def stack(cls, recallers: Sequence["Recaller"]) -> "Recaller":
        """One batch of recallers of one network and mode, all in the cue or all past it.

        The batch shares no array it could change with the recallers: stepping replaces
        its arrays rather than writing into them, so a batch of one shares its recaller's.
        """
        first = recallers[0]
        batch = cls(first.net, 0, first.mode, first.cue_steps)
        batch.t, batch.hidden_t = first.t, first.hidden_t

        def joined(arrays: list[np.ndarray]) -> np.ndarray:
            return arrays[0] if len(arrays) == 1 else np.concatenate(arrays)

        batch.zhat = joined([r.zhat for r in recallers])
        if first.drive is not None:
            batch.drive = joined([r.drive for r in recallers])
        if first.past is not None:
            batch.past = joined([r.past for r in recallers])
        if all(r.next_prior is not None for r in recallers):
            batch.next_prior = joined([r.next_prior for r in recallers])
            batch.next_expected = joined([r.next_expected for r in recallers])
        return batch

    def advance_as(self, batch: "Recaller", i: int) -> None:
        """Take the state of row i of ``batch``, stacked from this recaller and stepped once
        (copies of a larger batch's rows, so that its arrays are free to go; the rows' steps
        may differ past the cue)."""
        self.t += 1
        if len(batch.zhat) == 1:  # a batch of one shares this recaller's arrays already
            self.zhat, self.drive, self.past = batch.zhat, batch.drive, batch.past
            self.next_prior, self.next_expected = batch.next_prior, batch.next_expected
            return
        row = slice(i, i + 1)
        self.zhat = batch.zhat[row].copy()
        self.drive = None if batch.drive is None else batch.drive[row].copy()
        self.past = None if batch.past is None else batch.past[row].copy()
        self.next_prior = None if batch.next_prior is None else batch.next_prior[row].copy()
        self.next_expected = None if batch.next_expected is None else batch.next_expected[row].copy()

    def lay_out(self) -> None:
        """Multiply by a contiguous copy of W_H^T from now on, taken now (`TemporalPC.prior`): for
        a batch of several rows recalled over many steps of a network no training changes meanwhile
        (training changes the weights in place; the copy does not follow). The products' rounding
        may differ from the transposed view's in the last float32 bits."""
        self.hidden_t = self.net.W_H.T.contiguous().numpy()  # torch's transposing copy: ~35 us against numpy's ~60

    def state(self) -> tuple:
        """What a step changes, to `restore` it: references, since stepping replaces these arrays
        rather than writing into them."""
        return self.t, self.zhat, self.drive, self.past, self.next_prior, self.next_expected

    def restore(self, state: tuple) -> None:
        """Back to a `state`: the steps since undone."""
        self.t, self.zhat, self.drive, self.past, self.next_prior, self.next_expected = state

    @property
    def infers_now(self) -> bool:
        return self.t < self.cue_steps or self.mode == "online"

    def step(self, x: np.ndarray | None) -> np.ndarray:
        """Advance one step given observation x (B, D); returns what was expected of it."""
        if self.t == 0 and (self.net.has_context or self.net.has_direct):
            if x is None:
                raise ValueError("step 0 needs an observation: it sets the context and direct inputs")
            self.drive = self.net.context_drive(self.net.context_of(x))
            self.past = self.net.initial_past(x)
            self.next_prior = None  # a forecast made before they were known
        if self.infers_now and x is None:
            raise ValueError(f"step {self.t} needs an observation in {self.mode} recall")
        if self.next_prior is None:
            self.forecast()
        prior, forecast = self.next_prior, self.next_expected
        if self.t < self.cue_steps:  # the cue: what it is, not what was predicted of it
            z = self.net.infer(prior, x, past=self.past)
            expected = self.net.observe(z, self.past)
        else:
            z = self.net.infer(prior, x, past=self.past) if self.mode == "online" else prior
            expected = forecast
        seen = x if self.infers_now else expected
        self.zhat, self.past, self.next_prior, self.next_expected = z, self.net.push(self.past, seen), None, None
        self.t += 1
        return expected

    def forecast(self) -> np.ndarray:
        """Prediction of the next observation, W_F f(W_H f(zhat)) (+ W_D p); kept for the next step."""
        if self.next_prior is None:
            self.next_prior = self.net.prior(self.zhat, past=self.past, drive=self.drive, hidden_t=self.hidden_t)
            self.next_expected = self.net.observe(self.next_prior, self.past)
        return self.next_expected


def run(
    net: TemporalPC,
    sequences: np.ndarray,
    mode: NetworkMode = "offline",
    cue_steps: int = 1,
    rng: np.random.Generator | None = None,
) -> np.ndarray:
    """Expectations (N, T, D) for normalised sequences (N, T, D) under one recall mode."""
    recaller = Recaller(net, len(sequences), mode, cue_steps, rng)
    return np.stack([recaller.step(sequences[:, t]) for t in range(sequences.shape[1])], axis=1)


def offline_recall(
    net: TemporalPC, cue: np.ndarray, horizon: int, rng: np.random.Generator | None = None
) -> np.ndarray:
    """Recall (N, horizon, D) from a normalised cue (N, T_n, D): the model's plan."""
    cue_steps = cue.shape[1]
    if horizon < cue_steps:
        raise ValueError(f"horizon {horizon} is shorter than the cue ({cue_steps} steps)")
    recaller = Recaller(net, len(cue), "offline", cue_steps, rng)
    out = [recaller.step(cue[:, t] if t < cue_steps else None) for t in range(horizon)]
    return np.stack(out, axis=1)


def relax_observation(
    net: TemporalPC, z: np.ndarray, x_hat: np.ndarray | None = None, steps: int | None = None
) -> np.ndarray:
    """Eq. 6: x-hat <- x-hat - gamma * eps_x with eps_x = x-hat - W_F f(z).

    By default x-hat starts at the forward prediction W_F f(z), where eps_x is zero and
    it stays: that is why recall uses the forward prediction directly.
    """
    gamma = net.config.inference_rate
    target = net.observe(z)
    x_hat = target.copy() if x_hat is None else np.array(x_hat, np.float32)
    for _ in range(net.config.inference_steps if steps is None else steps):
        x_hat -= gamma * (x_hat - target)
    return x_hat
