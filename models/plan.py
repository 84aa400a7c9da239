"""Plan recall (beyond the paper): a plan set by the cue, what the memory's offline recall adds to
it, for the skill it recognises, and the episode's departure from that plan carried forward.

Why: where every episode differs, online recall reads the arm's last motion, so after a locked
joint it expects the arm to stay where it is; an expectation that returns to a plan fixed at the
cue keeps expecting the plan's motion and sees the lock (docs/varied_levers.md). The expectation
of step t of an episode recognised as skill s, with context c (the cue's context channels) and
departures d_t = x_t - plan_t, is

    plan_t  = B_s [e_t, e_t (x) c, 1] + R_s [f(z_t), 1]
    x_hat_t = plan_t + A_s [d_{t-1}, ..., d_{t-L}, 1]

- recognition: a softmax regression of the skill on the first observation (the cue);
- B_s, the input pathway (the tPC's B u, one map per step): the plan as a linear function of
  the context, the step's one-hot e_t giving each step its own;
- R_s: what the network's offline hidden states z_t, recalled from the cue, add to it, fitted on
  the part of the demonstrations B_s leaves (cross-fitted: from maps that did not see them);
- A_s, departure pathways (per skill or pooled, 1-3 lags, chosen by cross-validation), fitted on
  departures from plans that did not see the episode (a plan's departures on its own
  demonstrations are smaller than a new episode's).

Each map is the fixed point of a delta rule on the demonstrations, solved in closed form (ridge,
as ``direct_init="least_squares"`` is). Without context channels B_s is each step's mean.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np
from sklearn.linear_model import LogisticRegression
from sklearn.preprocessing import StandardScaler

from neural_asm.models.one_step import episode_folds, fit_one_step
from neural_asm.models.recall import Recaller
from neural_asm.models.step_maps import apply_maps, input_features, ridge_maps, step_codes, with_one
from neural_asm.models.tpc import TemporalPC

# The maps are cross-fitted inside cross-fitted folds (`PlanMemory.fit`): with three demonstrations
# of a skill every inner fold still holds one of it.
MIN_DEMONSTRATIONS = 3


def check_demonstrations(skills: Sequence[str]) -> None:
    """Refuse, before any training, skills (one per demonstration) a plan memory cannot be fitted on."""
    names, counts = np.unique(np.asarray(skills, dtype=str), return_counts=True)
    few = {str(n): int(c) for n, c in zip(names, counts) if c < MIN_DEMONSTRATIONS}
    if few:
        raise ValueError(f"a plan memory needs at least {MIN_DEMONSTRATIONS} demonstrations of every skill (its maps "
                         f"are cross-fitted); too few of: {', '.join(f'{n} ({c})' for n, c in few.items())}")


@dataclass(frozen=True)
class PlanMemory:
    """The maps of plan recall; K skills, D channels, C context channels, H hidden units, T
    demonstrated steps, L lags."""

    skills: tuple[str, ...]
    context: tuple[int, ...]  # the context channels' indices among the D
    recognition: np.ndarray  # (K, D + 1): skill logits of the cue [x_0, 1]
    inputs: np.ndarray  # (K, T * (C + 1) + 1, D): B_s
    readouts: np.ndarray  # (K, H + 1, D): R_s
    departures: np.ndarray  # (K, L * D + 1, D): A_s

    def __post_init__(self) -> None:
        k, d = len(self.skills), self.recognition.shape[1] - 1
        if self.recognition.shape != (k, d + 1):
            raise ValueError(f"plan recognition has shape {self.recognition.shape} for {k} skill(s)")
        if any(not 0 <= i < d for i in self.context):
            raise ValueError(f"plan context channels {self.context} are not among {d} channels")
        for name, rows in (("inputs", lambda n: n % (len(self.context) + 1) == 0),
                           ("readouts", lambda n: n > 0), ("departures", lambda n: n >= d and n % d == 0)):
            a = getattr(self, name)
            if a.ndim != 3 or a.shape[::2] != (k, d) or not rows(a.shape[1] - 1):
                raise ValueError(f"plan {name} have shape {a.shape} for {k} skill(s), {d} channels "
                                 f"and {len(self.context)} context channel(s)")

    @property
    def lags(self) -> int:
        return (self.departures.shape[1] - 1) // (self.recognition.shape[1] - 1)

    @property
    def steps(self) -> int:
        return (self.inputs.shape[1] - 1) // (len(self.context) + 1)

    @classmethod
    def fit(cls, net: TemporalPC, x: np.ndarray, skills: Sequence[str] | None, context: Sequence[int] = (),
            seed: int = 0, with_states: bool = True) -> "PlanMemory":
        """Fit on normalised demonstrations x (N, T, D) of the given skills (None: one skill)
        whose channels `context` describe the episode's context. Without `with_states` R_s is
        zero: the plan is the input pathway's alone, the network's part taken out (an ablation)."""
        labels = np.asarray(["all"] * len(x) if skills is None else skills, dtype=str)
        names = tuple(str(s) for s in np.unique(labels))
        skill = np.array([names.index(s) for s in labels])
        inputs = input_features(x[:, None, 0, list(context)], step_codes(np.arange(x.shape[1]), x.shape[1])[None])
        states = _offline_states(net, x)

        def maps(rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
            b = ridge_maps(inputs[rows], x[rows], labels[rows], names)
            if not with_states:
                return b, np.zeros((len(names), states.shape[2] + 1, x.shape[2]))
            left = np.empty_like(x[rows])
            for train, test in episode_folds(labels[rows], seed):
                fold = ridge_maps(inputs[rows][train], x[rows][train], labels[rows][train], names)
                left[test] = x[rows][test] - apply_maps(fold, inputs[rows][test], skill[rows][test])
            return b, ridge_maps(states[rows], left, labels[rows], names)

        b, r = maps(np.arange(len(x)))
        departures = np.empty_like(x)
        for train, test in episode_folds(labels, seed):
            b_fold, r_fold = maps(train)
            departures[test] = x[test] - apply_maps(b_fold, inputs[test], skill[test]) - apply_maps(r_fold, states[test], skill[test])
        one_step = fit_one_step(departures, labels, seed)
        pathways = np.stack([one_step.models[s].weights[:, : x.shape[2]] for s in names])
        return cls(names, tuple(int(i) for i in context), _fit_recognition(x[:, 0], labels, names), b, r, pathways)

    def recognise(self, cue: np.ndarray) -> np.ndarray:
        """(B,) index of the skill each normalised first observation (B, D) is recognised as."""
        return np.argmax(with_one(cue) @ self.recognition.T, axis=1)

    def read(self, z: np.ndarray, t: np.ndarray, skill: np.ndarray, cue: np.ndarray) -> np.ndarray:
        """The plan (B, D) at each row's step t (B,) from hidden states z (B, H) and the
        normalised cue (B, D); past the demonstrations' length the last step's map holds."""
        return (apply_maps(self.inputs, input_features(cue[:, list(self.context)], step_codes(t, self.steps)), skill)
                + apply_maps(self.readouts, np.tanh(z), skill))

    def depart(self, past: np.ndarray, skill: np.ndarray) -> np.ndarray:
        """The departure expected next (B, D) from the last L departures, newest first (B, L * D)."""
        return apply_maps(self.departures, past, skill)


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


def _offline_states(net: TemporalPC, x: np.ndarray) -> np.ndarray:
    """(N, T, H): f(z_t) of the network's offline recall from each sequence's first observation."""
    recaller = Recaller(net, len(x), "offline", 1)
    states = []
    for t in range(x.shape[1]):
        recaller.step(x[:, t] if t == 0 else None)
        states.append(np.tanh(recaller.zhat).astype(np.float64))
    return np.stack(states, axis=1)


class PlanRecaller:
    """A batch's plan recall, one step at a time, with `Recaller`'s interface: the plan of the skill
    recognised at the cue, plus the departure pathways. Rows may be at different steps (a batch
    of served sessions): each keeps its own."""

    mode = "plan"
    cue_steps = 1

    def __init__(self, net: TemporalPC, memory: PlanMemory, batch: int, rng: np.random.Generator | None = None) -> None:
        self.memory = memory
        self.offline = Recaller(net, batch, "offline", 1, rng)
        self.steps = np.zeros(batch, dtype=int)  # each row's step
        self.skill = np.zeros(batch, dtype=int)  # recognised at the cue
        self.cue = np.zeros((batch, memory.recognition.shape[1] - 1))  # the first observation
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
        batch.cue = np.concatenate([r.cue for r in recallers])
        if first.past is not None:
            batch.past = np.concatenate([r.past for r in recallers])
        if all(r.next_expected is not None for r in recallers):
            batch.next_expected = np.concatenate([r.next_expected for r in recallers])
        return batch

    def advance_as(self, batch: "PlanRecaller", i: int) -> None:
        """Take the state of row i of ``batch``, stacked from this recaller and stepped once."""
        self.offline.advance_as(batch.offline, i)
        row = slice(i, i + 1)
        self.steps, self.skill, self.cue = batch.steps[row].copy(), batch.skill[row].copy(), batch.cue[row].copy()
        self.past = None if batch.past is None else batch.past[row].copy()
        self.next_expected = None if batch.next_expected is None else batch.next_expected[row].copy()

    def step(self, x: np.ndarray | None) -> np.ndarray:
        """Advance one step given observation x (B, D); returns what was expected of it."""
        if x is None:
            raise ValueError(f"step {self.t} needs an observation in plan recall: departures are measured on it")
        x = np.asarray(x, np.float64)
        if self.t == 0:
            self.skill, self.cue = self.memory.recognise(x), x
            self.offline.step(x)
            expected = plan = self.memory.read(self.offline.zhat, self.steps, self.skill, self.cue)
        else:
            expected = self.forecast()
            self.offline.step(None)
            plan = self.memory.read(self.offline.zhat, self.steps, self.skill, self.cue)
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
            plan = self.memory.read(self.offline.next_prior, self.steps, self.skill, self.cue)
            self.next_expected = plan + self.memory.depart(self.past, self.skill)
        return self.next_expected
