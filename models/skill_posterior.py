"""Inference over skills: which skill's expectation explains the steps so far, and a step's fault
energy against the skills still plausible.

This is contextual inference. In the paper's contextual experiment a skill's context is inferred
from cues; the COIN model of motor memory (Heald, Lengyel and Wolpert, Nature 2021) keeps a
posterior over contexts, each with its own memory, updated by how well each predicts what is
observed. Here each skill k gives at step t an energy E_k,t (its residuals divided by the skill's
own spreads at that step, squared and summed) and a log normaliser L_k,t (the sum of their log
variances). The step's log-likelihood under skill k is then -(E_k,t + L_k,t) / 2, and

    p_t(k) ∝ [(1 - ε) p_t-1(k) + ε / K] · exp(-(E_k,t + L_k,t) / 2).

The forgetting ε spreads a little of the mass back over every skill at each step, so that a
posterior sure of one skill can turn to another that explains the later steps better. It is a
trade: it also lets a failing run be re-explained by another skill (docs/kitting.md).

Why a posterior rather than the cue: a skill recognised from the first observations adopts
whatever those say. A skill-5 segment started with an empty gripper is first recognised as an
empty-gripper skill, and its failure then passes as that skill's normal (docs/kitting.md).

The fault energy of step t is the step's surprise under the skills still plausible before it:

    E_t = -2 log Σ_k w_k exp(-E_k,t / 2),   w_k ∝ q_t(k) exp(-L_k,t / 2),

where q_t is the posterior carried to step t (forgetting applied) and the weights are normalised.
When one skill holds the posterior, E_t is that skill's energy. When no plausible skill explains
the step, every E_k,t is large, and so is E_t: a run that follows no skill's course is a fault,
not another skill's normal. Unlike the energy of the single most probable skill, E_t does not
jump when two skills are close. But it lets a skill with little posterior mass explain a step
whose energy under it is lower by more than twice its log-odds, and a term with many
heavy-tailed channels gives it many such chances: on the kitting data the skill memory scores
better by the most probable skill's energy (``rule="most_probable"``, its default; docs/kitting.md).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property
from typing import Literal, Sequence

import numpy as np

# The share of the posterior spread back over every skill at each step. None by default: on the
# kitting data a forgetting of 0.01 per step let a failed run be re-explained by another skill (mean
# AUROC 0.91-0.96 against 0.97 without, docs/kitting.md). A session that spans several skills needs
# some, so that it can re-recognise.
FORGETTING = 0.0
# The weight, counted in episodes, of the pooled spread in each skill's spread: a skill with
# one or two calibration episodes borrows most of its spread from every skill's.
PRIOR_EPISODES = 2.0
Rule = Literal["surprise", "most_probable"]


@dataclass(frozen=True)
class SkillSpreads:
    """Each skill's spread at each step and channel of one residual (K, T, D): the precisions
    the skill's energy is weighed by. Past step T the last step's spreads hold.

    With ``nu`` the residual is held to a Student-t of ``nu`` (> 2) degrees of freedom instead of
    a Gaussian, of the same variance (scale ``spread * sqrt((nu - 2) / nu)``): a step far off adds
    about the log of its size to the energy, not its square, so that a normal episode's isolated
    spike does not outweigh a course that is off for many steps.

    With ``precision`` (Gaussian only) the channels are weighed together, as the product's other
    calibrations weigh a step's errors: the residual over the spread, ``z``, scores ``z^T P_t z``
    with ``P_t`` the step's precision matrix of normal ``z`` (every skill's), so that channels
    that move together in normal episodes (speeds, force and torque) are not counted twice."""

    skills: tuple[str, ...]
    spread: np.ndarray  # (K, T, D) the residual's RMS
    nu: float | None = None  # None: Gaussian
    precision: np.ndarray | None = None  # (T, D, D) of the residual over the spread; None: channel by channel

    def __post_init__(self) -> None:
        if self.nu is not None and not self.nu > 2:
            raise ValueError(f"a Student-t's degrees of freedom must be > 2 (a finite variance), got {self.nu}")
        if self.nu is not None and self.precision is not None:
            raise ValueError("a term is held to a Student-t channel by channel, or weighed by precision matrices: not both")

    @classmethod
    def estimate(cls, residuals: np.ndarray, labels: Sequence[str], skills: Sequence[str], floor: float,
                 prior_episodes: float = PRIOR_EPISODES) -> "SkillSpreads":
        """Spreads from normal episodes' residuals (N, K, T, D) against every skill's expectation,
        each episode labelled with its skill: skill k's spread is the RMS of its own episodes'
        residuals against its expectation, shrunk towards the RMS over every episode's own skill,
        counted as ``prior_episodes`` episodes."""
        labels = np.asarray(labels).astype(str)
        unknown = sorted(set(labels.tolist()) - set(skills))
        if unknown:
            raise ValueError(f"calibration episodes of skill(s) {unknown} the memory does not know: {list(skills)}")
        index = np.array([list(skills).index(s) for s in labels])
        own = residuals[np.arange(len(labels)), index].astype(np.float64) ** 2  # (N, T, D)
        pooled = own.mean(axis=0)
        spread = np.stack([(own[index == k].sum(axis=0) + prior_episodes * pooled) / ((index == k).sum() + prior_episodes)
                           for k in range(len(skills))])
        return cls(tuple(skills), np.maximum(np.sqrt(spread), floor))

    def at(self, steps: np.ndarray | int, rows: np.ndarray | slice = slice(None)) -> np.ndarray:
        """(R, S, D) the spreads of the skills ``rows`` (all K by default) at ``steps`` (S,), or at one step (S = 1)."""
        return _pick(self.spread, steps, rows)

    def scale(self, steps: np.ndarray | int, rows: np.ndarray | slice = slice(None)) -> np.ndarray:
        """(R, S, D) what residuals are divided by: the spread, or the Student-t's scale."""
        return _pick(self._scales, steps, rows)

    @cached_property
    def _scales(self) -> np.ndarray:
        """(K, T, D) `scale` at every step, computed once: a served step picks its own from it."""
        return self.spread if self.nu is None else self.spread * np.sqrt((self.nu - 2) / self.nu)

    @cached_property
    def _t_scales(self) -> np.ndarray:
        """(K, T, D) a Student-t's scale times sqrt(nu): ``(r / it)²`` is its ``z² / nu``, in one division."""
        return self._scales * np.sqrt(self.nu)

    @cached_property
    def _log_normalisers(self) -> np.ndarray:
        """(K, T) `log_normaliser` at every step, computed once."""
        log_variances = 2 * np.log(self._scales).sum(axis=-1)
        if self.precision is None:
            return log_variances
        steps = np.minimum(np.arange(self.spread.shape[1]), len(self.precision) - 1)
        return log_variances - np.linalg.slogdet(self.precision)[1][steps][None]

    def energy(self, residuals: np.ndarray, steps: np.ndarray | int, rows: np.ndarray | slice = slice(None)) -> np.ndarray:
        """(..., R, S) energies of residuals (..., R, S, D) against the skills ``rows`` at ``steps`` (S,, or one):
        -2 log-likelihood less the normaliser, `Σ z²` (Gaussian), `z^T P_t z` (with precision matrices)
        or `(ν + 1) Σ log(1 + z² / ν)`."""
        if self.precision is not None:
            z = residuals / self.scale(steps, rows)
            at = np.minimum(steps, len(self.precision) - 1)
            weighed = np.matmul(z[..., None, :], self.precision[np.atleast_1d(at)])[..., 0, :]  # z^T P_t (einsum's 2x)
            return np.add.reduce(weighed * z, axis=-1)
        if self.nu is None:
            # .sum without its Python wrapper: a served step's every microsecond counts
            return np.add.reduce(np.square(residuals / self.scale(steps, rows)), axis=-1)
        return (self.nu + 1) * np.add.reduce(np.log1p(np.square(residuals / _pick(self._t_scales, steps, rows))), axis=-1)

    def log_normaliser(self, steps: np.ndarray | int, rows: np.ndarray | slice = slice(None)) -> np.ndarray:
        """(R, S) the skills' sums of log squared scales at ``steps`` (the variances, Gaussian), less
        the log-determinant of the step's precision matrix where the channels are weighed together."""
        return _pick(self._log_normalisers, steps, rows)


def _pick(table: np.ndarray, steps: np.ndarray | int, rows: np.ndarray | slice) -> np.ndarray:
    """(R, S, ...) a per-skill, per-step table's (K, T, ...) rows at ``steps`` (S,), the last step's
    past its end: the entries asked for alone, not every step of the rows first. One step (an
    int, S = 1) of rows given as a slice is a view: what a served step asks."""
    if isinstance(steps, int):
        at = min(steps, table.shape[1] - 1)
        return table[rows, at: at + 1] if isinstance(rows, slice) else table[np.asarray(rows), at: at + 1]
    at = np.minimum(steps, table.shape[1] - 1)
    return table[rows, at] if isinstance(rows, slice) else table[np.asarray(rows)[:, None], at[None, :]]


def _logsumexp(a: np.ndarray, keepdims: bool = False) -> np.ndarray:
    """log(sum(exp(a))) over the skills (axis 1): numpy's pairwise log-add-exp, ~1 us for a
    session's 7 skills where a max-shifted sum costs ~4 (and scipy's ~300: more than the rest of
    a served step)."""
    return np.logaddexp.reduce(a, axis=1, keepdims=keepdims)


class SkillPosterior:
    """A batch's posterior over K skills (B, K), one step at a time."""

    def __init__(self, batch: int, skills: int, forgetting: float = FORGETTING) -> None:
        if not 0 <= forgetting < 1:
            raise ValueError(f"forgetting must be in [0, 1), got {forgetting}")
        self.forgetting = forgetting
        self.log_p = np.full((batch, skills), -np.log(skills))
        self.rows = np.arange(batch)  # for picking each row's skill

    def carried(self) -> np.ndarray:
        """(B, K) log posterior carried to the next step: the forgetting applied."""
        k = self.log_p.shape[1]
        if self.forgetting == 0:
            return self.log_p
        return np.logaddexp(np.log1p(-self.forgetting) + self.log_p, np.log(self.forgetting / k))

    def energy(self, energies: np.ndarray, log_normaliser: np.ndarray, rule: Rule = "surprise") -> np.ndarray:
        """(B,) the fault energy of a step, from each skill's energy (B, K) and log normaliser
        (K,) or (B, K), before the step updates the posterior (the module's docstring)."""
        prior = self.carried()
        if rule == "most_probable":
            return energies[self.rows, prior.argmax(axis=1)]
        weights = prior - log_normaliser / 2
        weights = weights - _logsumexp(weights, keepdims=True)
        return -2 * _logsumexp(weights - energies / 2)

    def step(self, energies: np.ndarray, log_normaliser: np.ndarray, rule: Rule = "surprise", first: bool = False,
             evidence: tuple[np.ndarray, np.ndarray] | None = None) -> np.ndarray:
        """(B,) a step's fault energy (`energy`), the posterior then updated by the step's
        ``evidence`` (energies and log normalisers of the terms that recognise the skill; None:
        the scored ones). With ``rule="most_probable"`` the first step (``first``), which nothing
        came before, is scored against the skill most probable after it."""
        evidence = (energies, log_normaliser) if evidence is None else evidence
        if first and rule == "most_probable":
            self.update(*evidence)
            return energies[self.rows, self.log_p.argmax(axis=1)]
        energy = self.energy(energies, log_normaliser, rule)
        self.update(*evidence)
        return energy

    def update(self, energies: np.ndarray, log_normaliser: np.ndarray) -> None:
        """Bayes' rule for one step's energies (B, K) and log normalisers."""
        log_p = self.carried() - (energies + log_normaliser) / 2
        self.log_p = log_p - _logsumexp(log_p, keepdims=True)

    @property
    def probabilities(self) -> np.ndarray:
        return np.exp(self.log_p)


def most_probable_before(after: np.ndarray) -> np.ndarray:
    """(N, T) the skill most probable before each step, from the posteriors after each step
    (N, K, T); at the first step, which nothing came before, after it: the skill whose energy
    ``rule="most_probable"`` scores (forgetting keeps the order of the skills)."""
    return np.concatenate([after[:, :, :1], after[:, :, :-1]], axis=2).argmax(axis=1)


def infer(energies: np.ndarray, log_normaliser: np.ndarray, forgetting: float = FORGETTING,
          rule: Rule = "surprise", evidence: tuple[np.ndarray, np.ndarray] | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Whole episodes' fault energies (N, T) and posteriors after each step (N, K, T), from each
    skill's energies (N, K, T) and log normalisers (K, T), as a session infers them step by step;
    ``evidence``: the energies and log normalisers the posterior is updated by, if not those.

    With ``rule="most_probable"`` a step's energy is that of the skill most probable before it
    (at the first step, after it: nothing came before)."""
    n, k, steps = energies.shape
    posterior = SkillPosterior(n, k, forgetting)
    out, after = np.empty((n, steps)), np.empty((n, k, steps))
    for t in range(steps):
        seen = None if evidence is None else (evidence[0][:, :, t], evidence[1][:, t])
        out[:, t] = posterior.step(energies[:, :, t], log_normaliser[:, t], rule, t == 0, seen)
        after[:, :, t] = posterior.probabilities
    return out, after
