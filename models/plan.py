"""Plan recall (beyond the paper): the memory's offline recall of a skill, read out for the skill
it recognises, and the episode's departure from that plan carried forward.

Why: where every episode differs, online recall reads the arm's last motion, so after a locked
joint it expects the arm to stay where it is; an expectation that returns to a plan fixed at the
cue keeps expecting the plan's motion and sees the lock (docs/varied_levers.md). The network's
offline hidden states hold such a plan, which W_F alone reads out poorly. Three linear maps,
each the fixed point of a delta rule on the demonstrations (solved in closed form, as
``direct_init="least_squares"`` is), read it:

- recognition: a softmax regression of the skill on the first observation (the cue);
- a readout per skill: the observation regressed on f(z_t) of offline recall from the cue and
  on the step's one-hot (the step's own offset, as the template rivals have);
- departure pathways per skill: the departure from the plan regressed on the last departures,
  fitted on departures from readouts that did not see the episode (a readout's departures on
  its own demonstrations are smaller than a new episode's).

At step t the expectation is R_s [f(z_t), e_t, 1] + A_s [d_{t-1}, ..., d_{t-L}, 1], with s the
skill recognised at the cue and d the departures seen so far (the first standing in for those before the start, as
the one-step rivals embed it).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np
from sklearn.linear_model import LogisticRegression, RidgeCV
from sklearn.preprocessing import StandardScaler

from models.detector_base import episode_folds
from models.one_step import fit_one_step
from models.recall import Recaller
from models.tpc import TemporalPC

READOUT_RIDGES = np.logspace(-2, 4, 13)


def _with_one(a: np.ndarray) -> np.ndarray:
    return np.concatenate([a, np.ones(a.shape[:-1] + (1,))], axis=-1)


@dataclass(frozen=True)
class PlanMemory:
    """The maps of plan recall; K skills, D channels, H hidden units, T demonstrated steps, L lags."""

    skills: tuple[str, ...]
    recognition: np.ndarray  # (K, D + 1): skill logits of the cue [x_0, 1]
    readouts: np.ndarray  # (K, H + T + 1, D): x_t = [f(z_t), e_t, 1] @ readouts[s]
    departures: np.ndarray  # (K, L * D + 1, D): d_t = [d_{t-1}, ..., d_{t-L}, 1] @ departures[s]

    def __post_init__(self) -> None:
        k, d = len(self.skills), self.recognition.shape[1] - 1
        if self.recognition.shape != (k, d + 1):
            raise ValueError(f"plan recognition has shape {self.recognition.shape} for {k} skill(s)")
        if self.readouts.ndim != 3 or self.readouts.shape[0] != k or self.readouts.shape[2] != d:
            raise ValueError(f"plan readouts have shape {self.readouts.shape} for {k} skill(s) and {d} channels")
        rows = self.departures.shape[1] - 1 if self.departures.ndim == 3 else -1
        if self.departures.shape[::2] != (k, d) or rows < d or rows % d:
            raise ValueError(f"plan departures have shape {self.departures.shape} for {k} skill(s) and {d} channels")

    @property
    def lags(self) -> int:
        return (self.departures.shape[1] - 1) // (self.recognition.shape[1] - 1)

    @classmethod
    def fit(cls, net: TemporalPC, x: np.ndarray, skills: Sequence[str] | None, seed: int = 0) -> "PlanMemory":
        """Fit on normalised demonstrations x (N, T, D) of the given skills (None: one skill)."""
        labels = np.asarray(["all"] * len(x) if skills is None else skills, dtype=str)
        names = tuple(str(s) for s in np.unique(labels))
        readouts = _fit_readouts(net, x, labels, names)
        departures = np.empty_like(x)
        for train, test in episode_folds(labels, seed):
            held_out = _fit_readouts(net, x[train], labels[train], names)
            departures[test] = x[test] - _plan(net, held_out, x[test], [names.index(s) for s in labels[test]])
        one_step = fit_one_step(departures, labels, seed)
        width = x.shape[2]
        pathways = np.stack([one_step.models[s].weights[:, :width] for s in names])
        return cls(names, _fit_recognition(x[:, 0], labels, names), readouts, pathways)

    def recognise(self, cue: np.ndarray) -> np.ndarray:
        """(B,) index of the skill each normalised first observation (B, D) is recognised as."""
        return np.argmax(_with_one(cue) @ self.recognition.T, axis=1)

    def read(self, z: np.ndarray, t: np.ndarray, skill: np.ndarray) -> np.ndarray:
        """The plan (B, D) at each row's step t (B,) from hidden states z (B, H); past the
        demonstrations' length the last step's offset holds."""
        step = step_codes(int(t.max()) + 1, self.readouts.shape[1] - 1 - z.shape[1])[t]
        return np.einsum("bf,bfd->bd", _with_one(np.concatenate([np.tanh(z), step], axis=1)), self.readouts[skill])

    def depart(self, past: np.ndarray, skill: np.ndarray) -> np.ndarray:
        """The departure expected next (B, D) from the last L departures, newest first (B, L * D)."""
        return np.einsum("bf,bfd->bd", _with_one(past), self.departures[skill])


def _fit_recognition(cue: np.ndarray, labels: np.ndarray, names: tuple[str, ...]) -> np.ndarray:
    """Softmax regression on the standardised cue, folded into one (K, D + 1) map of the raw cue."""
    if len(names) == 1:
        return np.zeros((1, cue.shape[1] + 1))
    scaler = StandardScaler().fit(cue)
    logistic = LogisticRegression(max_iter=5000).fit(scaler.transform(cue), labels)
    weights = logistic.coef_ / scaler.scale_
    bias = logistic.intercept_ - weights @ scaler.mean_
    if len(names) == 2:  # sklearn gives one logit, of the second class, for two
        weights, bias = np.vstack([-weights, weights]) / 2, np.array([-bias[0], bias[0]]) / 2
    order = [list(logistic.classes_).index(s) for s in names]
    return np.hstack([weights, bias[:, None]])[order]


def _offline_features(net: TemporalPC, x: np.ndarray) -> np.ndarray:
    """(N, T, H): f(z_t) of the network's offline recall from each sequence's first observation."""
    recaller = Recaller(net, len(x), "offline", 1)
    states = []
    for t in range(x.shape[1]):
        recaller.step(x[:, t] if t == 0 else None)
        states.append(np.tanh(recaller.zhat).astype(np.float64))
    return np.stack(states, axis=1)


def step_codes(length: int, steps: int) -> np.ndarray:
    """(length, steps): the one-hot of each step among the demonstrations' `steps`, the last
    step's past their end."""
    return np.eye(steps)[np.minimum(np.arange(length), steps - 1)]


def _features(f: np.ndarray, steps: int) -> np.ndarray:
    n, t, _ = f.shape
    return np.concatenate([f, np.broadcast_to(step_codes(t, steps), (n, t, steps))], axis=2)


def _fit_readouts(net: TemporalPC, x: np.ndarray, labels: np.ndarray, names: tuple[str, ...]) -> np.ndarray:
    features = _features(_offline_features(net, x), x.shape[1])
    out = []
    for s in names:
        rows = labels == s
        ridge = RidgeCV(alphas=READOUT_RIDGES).fit(features[rows].reshape(-1, features.shape[2]),
                                                   x[rows].reshape(-1, x.shape[2]))
        out.append(np.vstack([ridge.coef_.T, ridge.intercept_[None]]))
    return np.stack(out)


def _plan(net: TemporalPC, readouts: np.ndarray, x: np.ndarray, skill: Sequence[int]) -> np.ndarray:
    """(N, T, D) plans of sequences x read out for their skills."""
    features = _with_one(_features(_offline_features(net, x), readouts.shape[1] - 1 - net.config.hidden_size))
    return np.einsum("ntf,nfd->ntd", features, readouts[np.asarray(skill)])


class PlanRecaller:
    """A batch's plan recall, one step at a time, with `Recaller`'s interface: the network's
    offline recall from the cue, read out for the recognised skill, plus the departure pathways.
    Rows may be at different steps (a batch of served sessions): each keeps its own."""

    mode = "plan"
    cue_steps = 1

    def __init__(self, net: TemporalPC, memory: PlanMemory, batch: int, rng: np.random.Generator | None = None) -> None:
        self.memory = memory
        self.offline = Recaller(net, batch, "offline", 1, rng)
        self.steps = np.zeros(batch, dtype=int)  # each row's step
        self.skill = np.zeros(batch, dtype=int)  # recognised at the cue
        self.past: np.ndarray | None = None  # the last L departures, newest first (B, L * D)
        self.next_expected: np.ndarray | None = None

    @property
    def t(self) -> int:
        return self.offline.t

    @property
    def net(self) -> TemporalPC:
        return self.offline.net

    @classmethod
    def stack(cls, recallers: Sequence["PlanRecaller"]) -> "PlanRecaller":
        """One batch of recallers of one network and memory, all at the cue or all past it."""
        first = recallers[0]
        batch = cls(first.net, first.memory, 0)
        batch.offline = Recaller.stack([r.offline for r in recallers])
        batch.steps = np.concatenate([r.steps for r in recallers])
        batch.skill = np.concatenate([r.skill for r in recallers])
        if first.past is not None:
            batch.past = np.concatenate([r.past for r in recallers])
        if all(r.next_expected is not None for r in recallers):
            batch.next_expected = np.concatenate([r.next_expected for r in recallers])
        return batch

    def advance_as(self, batch: "PlanRecaller", i: int) -> None:
        """Take the state of row i of ``batch``, stacked from this recaller and stepped once."""
        self.offline.advance_as(batch.offline, i)
        row = slice(i, i + 1)
        self.steps, self.skill = batch.steps[row].copy(), batch.skill[row].copy()
        self.past = None if batch.past is None else batch.past[row].copy()
        self.next_expected = None if batch.next_expected is None else batch.next_expected[row].copy()

    def step(self, x: np.ndarray | None) -> np.ndarray:
        """Advance one step given observation x (B, D); returns what was expected of it."""
        if x is None:
            raise ValueError(f"step {self.t} needs an observation in plan recall: departures are measured on it")
        x = np.asarray(x, np.float64)
        if self.t == 0:
            self.skill = self.memory.recognise(x)
            self.offline.step(x)
            expected = plan = self.memory.read(self.offline.zhat, self.steps, self.skill)
        else:
            expected = self.forecast()
            self.offline.step(None)
            plan = self.memory.read(self.offline.zhat, self.steps, self.skill)
        departure = x - plan
        lags = self.memory.lags
        self.past = np.tile(departure, lags) if self.past is None else np.concatenate(
            [departure, self.past[:, : (lags - 1) * departure.shape[1]]], axis=1)
        self.steps = self.steps + 1
        self.next_expected = None
        return expected

    def forecast(self) -> np.ndarray:
        """Expectation of the next observation: the plan's next step plus the departure expected."""
        if self.next_expected is None:
            if self.past is None:
                raise ValueError("plan recall forecasts only once the cue has been seen")
            self.offline.forecast()
            plan = self.memory.read(self.offline.next_prior, self.steps, self.skill)
            self.next_expected = plan + self.memory.depart(self.past, self.skill)
        return self.next_expected
