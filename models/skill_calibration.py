"""How a skill memory scores a step, and what its calibration keeps: the terms scored and the
rule a step not told is scored by (`SkillScoring`, chosen round by round on the kitting data:
docs/kitting.md), each skill's course, spreads, energy scales and thresholds (`SkillCalibration`,
kept by the checkpoint), and the normal episodes' energies calibration pools (`EpisodeEnergies`).
The memory that calibrates and scores is `models.skill_context.SkillMemory`."""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property
from types import MappingProxyType
from typing import Any, Literal, NamedTuple, Sequence

import numpy as np

from neural_asm.models.skill_posterior import FORGETTING, Rule, SkillSpreads

TERMS = ("course", "dynamics")
# The terms held to a Student-t by default, and its degrees of freedom: the dynamics term, whose
# normal residuals are heavy-tailed (docs/kitting.md, "Round 2").
TAILS = MappingProxyType({"dynamics": 4.0})
Course = Literal["recalled", "mean"]
# The normal episodes a skill needs for its own energy scale (`skill_scales`); with fewer it takes
# every skill's.
MIN_SCALE_EPISODES = 3


def segment_peaks(energies: np.ndarray, lengths: np.ndarray) -> np.ndarray:
    """Each episode's peak energy (N,) over its own first ``lengths`` steps (not the samples that pad it)."""
    return np.array([e[:n].max() for e, n in zip(energies, lengths)])


def skill_scales(peaks: np.ndarray, skills: np.ndarray, n_skills: int, minimum: int = MIN_SCALE_EPISODES) -> np.ndarray:
    """(K,) each skill's normal energy scale: the median of its normal episodes' peaks told their
    skill (``peaks``, ``skills`` their rows), or of every episode's for a skill with fewer than
    ``minimum``."""
    pooled = float(np.median(peaks))
    return np.array([float(np.median(peaks[skills == k])) if (skills == k).sum() >= minimum else pooled
                     for k in range(n_skills)])


class EpisodeEnergies(NamedTuple):
    """Normal episodes' energies as calibration pools them: not told step by step (its scale is
    set only once every episode's told peaks are in), told as peaks."""

    inferred: np.ndarray  # (N, T) not told, each step the energy of the skill ``picked``
    picked: np.ndarray  # (N, T) that skill's row
    told: np.ndarray  # (N,) peaks told their skills
    skills: np.ndarray  # (N,) those skills' rows
    lengths: np.ndarray  # (N,) each episode's own steps

    def inferred_peaks(self, cal: "SkillCalibration") -> np.ndarray:
        """(N,) peaks not told, in ``cal``'s units."""
        return segment_peaks(cal.in_units(self.inferred, self.picked), self.lengths)


@dataclass(frozen=True)
class SkillScoring:
    """How a skill memory scores a step: the ``terms`` scored, the ``course`` they are held to
    (see `SkillMemory.courses`), the terms whose likelihood updates the posterior
    (``recognised_by``; none: the scored ones), its ``forgetting``, the ``rule`` a step not told
    is scored by (`models.skill_posterior`), and the terms held to a Student-t of the given
    degrees of freedom (``tails``; the others Gaussian: `SkillSpreads`).

    The defaults are the variant that did best not told on the kitting data (docs/kitting.md):
    the demonstrations' mean course (the network's recall drifts from it) and the network's
    dynamics scored, the skill recognised by the course, no forgetting (chosen after the first
    three splits were seen); the dynamics residual held to a Student-t of 4 degrees of freedom
    and, not told, the most probable skill's energy scored (adopted by a rule written before
    three fresh splits were run: +0.014 mean AUROC not told, told unchanged). The terms in
    ``correlated`` are weighed with their channels' correlations (per-step precision matrices,
    `SkillSpreads`), the others channel by channel: none by default (the course correlated did not
    rank better told on three fresh splits: docs/kitting.md, "Round 4, H6"). With ``scaled``, not
    told, each step's energy is taken in units of the scale of the skill it is the energy of (the
    median of that skill's normal peaks told it), so that one threshold does not hold a skill learnt
    from few demonstrations, whose normal steps score several times higher, and the others alike:
    off by default (on three fresh splits it ranked better on each, +0.022 mean AUROC, but flagged
    5 % of one split's normal segments against the 2 % its rule allowed: docs/kitting.md, "Round 5")."""

    terms: tuple[str, ...] = TERMS
    course: Course = "mean"
    recognised_by: tuple[str, ...] = ("course",)
    forgetting: float = FORGETTING
    rule: Rule = "most_probable"
    tails: tuple[tuple[str, float], ...] = tuple(TAILS.items())
    correlated: tuple[str, ...] = ()
    scaled: bool = False

    def check(self) -> None:
        """A ValueError naming a term that is not one, or one both held to a Student-t and correlated."""
        unknown = [t for t in (*self.terms, *self.recognised_by, *dict(self.tails), *self.correlated) if t not in TERMS]
        if unknown or not self.terms:
            raise ValueError(f"terms must be among {TERMS}, got {list(self.terms)}, {list(self.recognised_by)}, "
                             f"{list(dict(self.tails))} and {list(self.correlated)}")
        both = sorted(set(dict(self.tails)) & set(self.correlated))
        if both:
            raise ValueError(f"term(s) {both} held to a Student-t channel by channel cannot also be correlated")


@dataclass
class SkillCalibration:
    """What scoring a memory's sessions needs beyond the network: the terms scored, each skill's
    course (normalised, K x T x D), each term's spreads per skill, and episode thresholds
    (a false-positive rate -> threshold): not told (`inferred`), told (one per skill, its own
    where it has enough threshold episodes for a split-conformal quantile, else every skill's)."""

    terms: tuple[str, ...]
    courses: np.ndarray
    spreads: dict[str, SkillSpreads]
    forgetting: float  # these three as `SkillScoring` set them (it holds their defaults)
    rule: Rule
    recognised_by: tuple[str, ...]  # the terms whose likelihood updates the posterior (none: every term)
    inferred: dict[float, float] = field(default_factory=dict)
    told: dict[float, np.ndarray] = field(default_factory=dict)  # fpr -> (K,)
    out_of_fold_episodes: int = 0  # demonstrations whose out-of-fold peaks joined the threshold episodes'
    scales: np.ndarray | None = None  # (K,) each skill's normal energy scale, not told (`SkillScoring.scaled`); None: 1

    def in_units(self, energies: np.ndarray, skills: np.ndarray | int) -> np.ndarray:
        """Energies not told in the units of the skills (rows) they are the energies of: divided by
        those skills' scales, or as they are without scales."""
        return energies if self.scales is None else energies / self.scales[skills]

    def scored(self, residuals: dict[str, np.ndarray], steps: np.ndarray | int, rows: np.ndarray | slice = slice(None)
               ) -> tuple[np.ndarray, np.ndarray, tuple[np.ndarray, np.ndarray] | None]:
        """The energies (..., R, S) of residuals per term (..., R, S, D) against the skills ``rows``
        (all K by default) at ``steps`` (S,; an int: one step) and those skills' log normalisers (R, S), summed over the
        terms scored; and what updates the posterior where it is not those (the same sums over
        `recognised_by`; None: the scored ones). Each term is weighed once."""
        used, own = self._plan
        energy = {t: self.spreads[t].energy(residuals[t], steps, rows) for t in used}
        norm = {t: self.spreads[t].log_normaliser(steps, rows) for t in used}

        def summed(terms: Sequence[str]) -> tuple[np.ndarray, np.ndarray]:
            total, normaliser = energy[terms[0]], norm[terms[0]]
            for t in terms[1:]:
                total, normaliser = total + energy[t], normaliser + norm[t]
            return total, normaliser

        return (*summed(self.terms), summed(self.recognised_by) if own else None)

    @cached_property
    def _plan(self) -> tuple[tuple[str, ...], bool]:
        """The terms `scored` weighs (each once), and whether the posterior has terms of its own:
        the same at every step of every session."""
        own = bool(self.recognised_by) and set(self.recognised_by) != set(self.terms)
        return tuple(dict.fromkeys((*self.terms, *self.recognised_by))), own

    def to_parts(self) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
        """The calibration as JSON metadata and named arrays, as a checkpoint stores it (no pickle)."""
        fprs = sorted(self.told)
        meta = {"terms": list(self.terms), "forgetting": self.forgetting, "rule": self.rule,
                "recognised_by": list(self.recognised_by), "spreads": sorted(self.spreads),
                "inferred": [[f, t] for f, t in sorted(self.inferred.items())], "told_fprs": fprs,
                "tails": {t: s.nu for t, s in self.spreads.items() if s.nu is not None},
                "out_of_fold_episodes": self.out_of_fold_episodes}
        arrays = {"courses": self.courses, **{f"spreads.{t}": s.spread for t, s in self.spreads.items()},
                  **{f"precision.{t}": s.precision for t, s in self.spreads.items() if s.precision is not None}}
        if fprs:
            arrays["told"] = np.stack([self.told[f] for f in fprs])
        if self.scales is not None:
            arrays["scales"] = self.scales
        return meta, arrays

    @classmethod
    def from_parts(cls, meta: dict[str, Any], arrays: dict[str, np.ndarray], skills: Sequence[str]) -> "SkillCalibration":
        """The calibration `to_parts` wrote, of a memory knowing ``skills``."""
        told, tails = arrays.get("told"), meta.get("tails", {})
        return cls(tuple(meta["terms"]), arrays["courses"],
                   {t: SkillSpreads(tuple(skills), arrays[f"spreads.{t}"], tails.get(t), arrays.get(f"precision.{t}"))
                    for t in meta["spreads"]},
                   float(meta["forgetting"]), meta["rule"], tuple(meta["recognised_by"]),
                   {float(f): float(t) for f, t in meta["inferred"]},
                   {float(f): told[i] for i, f in enumerate(meta["told_fprs"])}, int(meta.get("out_of_fold_episodes", 0)),
                   arrays.get("scales"))
