"""One memory for every skill that knows each skill's course: told the skill, or inferring it.

Why: a network whose expectation is set by the episode's first observation adopts whatever that
observation says. On the Baxter kitting data a skill-5 segment started with an empty gripper is
recalled as an empty-gripper skill, and its failure passes (docs/kitting.md). Here the one network
is told the skill by a one-hot skill cue. The cue is observed, as the paper's contextual experiment
observes its visual cue, and it drives the prior as the tPC's context input,
`z_prior = W_H f(zhat) + W_C c` (`TPCConfig.context_input`). Each skill k then gives two
expectations of step t:

- its **course**, which does not depend on the episode's cue: the network's offline recall from the
  skill's own start (its demonstrations' mean first observation, with its cue), or the
  demonstrations' mean course of the skill, kept with the memory (on the kitting data the
  recall drifts from the skill's course over 6 s and the mean does better: docs/kitting.md);
- its **dynamics**: online recall under the skill's cue (z inferred from every step), which
  expects the next step from the last.

Each term's residuals are divided by the skill's own spreads at that step (from held-out normal
episodes: `models.skill_posterior.SkillSpreads`), and the skill's energy is the sum of their
squares (the dynamics term's, by default, a Student-t's negative log-likelihood: its normal
residuals are heavy-tailed). A session told the skill is scored by that skill's energy. One not
told keeps a posterior over the skills and scores the step against the most probable skill, or
its surprise under the skills still plausible (`models.skill_posterior`: contextual inference, as
in the COIN model of Heald et al., Nature 2021).

The network is a `NeuralASM` over the observation channels and the K cue channels (named
`skill:<name>`), so it is trained, checkpointed and recalled as any other model. What this
module adds is the cue, the courses, the spreads per skill and the decision (how a step is scored
and what calibration keeps: `models.skill_calibration`); `SkillMemory.session` is the served step
(`models.skill_session`).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, Callable, Mapping, Sequence

import numpy as np
from tqdm.auto import tqdm

from neural_asm.models.asm import NeuralASM
from neural_asm.models.calibration import conformal_episode_threshold, error_precision
from neural_asm.models.config import DEFAULT_RATE_HZ, SCORING, TPCConfig
from neural_asm.models.cross_fit import CrossFit, conformal_minimum, group_folds
from neural_asm.models.normaliser import Normaliser
from neural_asm.models.skill_calibration import (TERMS, Course, EpisodeEnergies, SkillCalibration, SkillScoring,
                                                 segment_peaks, skill_scales)
from neural_asm.models.skill_posterior import SkillSpreads, infer, most_probable_before

if TYPE_CHECKING:
    from neural_asm.models.skill_session import SkillSession

CUE_PREFIX = "skill:"
Labels = Sequence[str] | np.ndarray  # each episode's skill: names, or an array of them


def cue_names(skills: Sequence[str]) -> tuple[str, ...]:
    return tuple(f"{CUE_PREFIX}{s}" for s in skills)


def skills_of(model: NeuralASM) -> tuple[str, ...]:
    """The skills a model's cue channels name (none: a model trained without skills)."""
    return tuple(c[len(CUE_PREFIX):] for c in model.context_channels if c.startswith(CUE_PREFIX))


def with_cue(x: np.ndarray, skill: np.ndarray, skills: int) -> np.ndarray:
    """Observations (N, T, D) with each episode's one-hot skill cue (N,) appended: (N, T, D + K)."""
    cue = np.zeros(x.shape[:-1] + (skills,))
    cue[np.arange(len(x)), ..., skill] = 1.0
    return np.concatenate([x, cue], axis=-1)


def cued_network(sequences: np.ndarray, channel_names: Sequence[str], labels: np.ndarray, skills: Sequence[str],
                 config: TPCConfig, progress: bool = False, provenance: dict | None = None,
                 rate_hz: float = DEFAULT_RATE_HZ) -> NeuralASM:
    """The one network trained on raw demonstrations (N, T, D), each with its skill's one-hot cue
    among ``skills`` (the cue's channels: a skill without demonstrations keeps an unseen cue)."""
    index = np.array([list(skills).index(s) for s in labels])
    cues = cue_names(tuple(skills))
    return NeuralASM.fit(with_cue(np.asarray(sequences, np.float64), index, len(skills)),
                         (*channel_names, *cues), config.with_(context_input=True), progress=progress,
                         labels=labels, context_channels=cues, rate_hz=rate_hz).noted(provenance or {})


def mean_courses(sequences: np.ndarray, labels: Sequence[str], skills: Sequence[str]) -> np.ndarray:
    """(K, T, D) each skill's mean course of its raw demonstrations (N, T, D)."""
    labels = np.asarray(labels).astype(str)
    return np.stack([np.asarray(sequences, np.float64)[labels == s].mean(axis=0) for s in skills])


def check_alike(demonstrations: np.ndarray, threshold: np.ndarray) -> None:
    """A ValueError unless the demonstrations cross-fitted and the threshold episodes have the same
    steps and channels: their peaks are pooled as peaks of one kind of episode."""
    if np.shape(demonstrations)[1:] != np.shape(threshold)[1:]:
        raise ValueError(f"cross-fitting pools peaks of episodes alike: the demonstrations are "
                         f"{np.shape(demonstrations)[1:]} (steps, channels), the threshold episodes "
                         f"{np.shape(threshold)[1:]}")


@dataclass(frozen=True)
class OutOfFold:
    """The raw demonstrations (N, T, D) a memory learnt, their skills and real steps, each one's
    fold, and per fold a memory that did not learn it: what cross-fitting the thresholds needs
    (`SkillMemory.calibrate`). A memory's energies on its own demonstrations are optimistic; a fold
    memory's on the fold it left out are not, and they add normal episodes to the held-out ones."""

    demonstrations: np.ndarray
    labels: np.ndarray
    lengths: np.ndarray
    fold: np.ndarray
    memories: tuple["SkillMemory", ...]

    @classmethod
    def fit(cls, memory: "SkillMemory", demonstrations: np.ndarray, labels: Labels,
            lengths: np.ndarray | None = None, groups: Sequence[object] | np.ndarray | None = None, folds: int = 5,
            seed: int = 0, fold_memory: Callable[[int, np.ndarray, np.ndarray], "SkillMemory"] | None = None) -> "OutOfFold":
        """Folds dealt by ``groups`` (each demonstration's run: no run on both sides; None: each
        demonstration its own) with ``seed``; fold k's memory from ``fold_memory(k, data, labels)``
        of its training part (default: `SkillMemory.fold`, a network trained afresh)."""
        data, labels = np.asarray(demonstrations, np.float64), np.asarray(labels).astype(str)
        if len(labels) != len(data):
            raise ValueError(f"{len(labels)} skill labels for {len(data)} demonstrations")
        fold = group_folds(np.arange(len(data)) if groups is None else groups, folds, seed)
        make = fold_memory or (lambda k, x, y: memory.fold(x, y))
        memories = tuple(make(k, data[fold != k], labels[fold != k]) for k in range(folds))
        steps = np.full(len(data), data.shape[1]) if lengths is None else np.asarray(lengths)
        return cls(data, labels, steps, fold, memories)


    @classmethod
    def crossing(cls, memory: "SkillMemory", cross_fit: CrossFit, progress: bool = False) -> "OutOfFold":
        """`fit` to what ``cross_fit`` holds (`models.cross_fit.CrossFit`: the demonstrations, their
        skills, folds, groups and seed), each fold memory a network trained as ``memory``'s was, one
        progress bar over the folds; a ValueError first unless the demonstrations are those the
        memory learnt, with their skills (`SkillMemory.check_learnt`)."""
        if cross_fit.labels is None:
            raise ValueError(f"the memory learnt the skills {list(memory.skills)}: cross-fitting needs each "
                             f"demonstration's skill")
        memory.check_learnt(cross_fit.demonstrations, cross_fit.labels)
        with tqdm(total=cross_fit.folds, desc="cross-fitting", unit="fold", disable=not progress) as bar:
            def fold_memory(k: int, x: np.ndarray, y: np.ndarray) -> SkillMemory:
                fitted = memory.fold(x, y)
                bar.update()
                return fitted

            return cls.fit(memory, cross_fit.demonstrations, cross_fit.labels, groups=cross_fit.groups,
                           folds=cross_fit.folds, seed=cross_fit.seed, fold_memory=fold_memory)


class SkillMemory:
    """One network told the skill by a cue, with each skill's course, spreads and thresholds."""

    def __init__(self, model: NeuralASM, means: np.ndarray) -> None:
        self.skills = skills_of(model)
        if not self.skills:
            raise ValueError("a skill memory needs a model trained with skill cues (SkillMemory.fit)")
        if means.ndim != 3 or means.shape[::2] != (len(self.skills), model.obs_size - len(self.skills)):
            raise ValueError(f"mean courses have shape {means.shape} for {len(self.skills)} skills")
        self.model = model
        self.means = np.asarray(means, np.float64)  # (K, T, D) each skill's mean course of its demonstrations, raw
        self.calibration: SkillCalibration | None = None
        self.width = self.means.shape[2]  # the observation channels, the cue's left out
        self.channel_names: tuple[str, ...] = model.channel_names[: self.width]
        self.observed = Normaliser(model.normaliser.mean[: self.width], model.normaliser.std[: self.width])

    @classmethod
    def fit(cls, sequences: np.ndarray, channel_names: Sequence[str], labels: Labels, config: TPCConfig,
            progress: bool = False, provenance: dict | None = None, rate_hz: float = DEFAULT_RATE_HZ) -> "SkillMemory":
        """Train the one network on raw demonstrations (N, T, D) of the named skills, each with its cue."""
        labels = np.asarray(labels).astype(str)
        if len(labels) != len(sequences):
            raise ValueError(f"{len(labels)} skill labels for {len(sequences)} demonstrations")
        skills = tuple(sorted(set(labels.tolist())))
        if len(skills) < 2:
            raise ValueError(f"a skill memory needs demonstrations of at least 2 skills, got {list(skills)}")
        model = cued_network(sequences, channel_names, labels, skills, config, progress, provenance, rate_hz)
        return cls(model, mean_courses(sequences, labels, skills))

    def fold(self, demonstrations: np.ndarray, labels: Labels, network: bool = True) -> "SkillMemory":
        """A memory that did not learn these raw demonstrations' complement: one trained as this
        one was (its configuration, seed and kept epochs) on ``demonstrations`` (N, T, D) of every
        skill it knows, with their mean courses; without ``network``, this one's network with their
        mean courses (all a memory scored by its course alone needs). A skill with no demonstration
        among them (every run of it left out) keeps this memory's course and a cue its network never
        saw: the fold memory is not asked to score it (`calibrate` leaves its episodes out)."""
        labels = np.asarray(labels).astype(str)
        learnt = [s for s in self.skills if s in set(labels.tolist())]
        means = self.means.copy()  # a skill not learnt keeps this memory's course
        means[[self.index(s) for s in learnt]] = mean_courses(demonstrations, labels, learnt)
        if not network:
            return SkillMemory(self.model, means)
        epochs = int(self.model.provenance.get("kept_epoch", self.model.config.epochs))
        model = cued_network(demonstrations, self.channel_names, labels, self.skills,
                             self.model.config.with_(epochs=epochs), provenance={"cross_fit": "fold network"},
                             rate_hz=self.model.rate_hz)
        return SkillMemory(model, means)

    def check_learnt(self, demonstrations: np.ndarray, labels: Labels) -> None:
        """A ValueError unless these raw demonstrations (N, T, D) and skills are those the memory
        learnt (their count and each skill's mean course): cross-fitting scores each with a memory
        trained as this one was without it, which other episodes would not test."""
        data, labels = np.asarray(demonstrations, np.float64), np.asarray(labels).astype(str)
        trained = self.model.provenance.get("sequences", len(data))
        learnt = (trained == len(data) == len(labels) and data.shape[1:] == self.means.shape[1:]
                  and set(labels.tolist()) == set(self.skills)
                  and np.allclose(mean_courses(data, labels, self.skills), self.means, rtol=1e-6, atol=1e-9))
        if not learnt:
            raise ValueError(f"cross-fitting needs the demonstrations the memory learnt ({trained} sequences of the "
                             f"skills {', '.join(self.skills)}); these {len(data)} are not: their count, skills or "
                             f"mean courses differ")

    def index(self, skill: str) -> int:
        """The skill's row, or a ValueError naming it and the skills known."""
        if skill not in self.skills:
            raise ValueError(f"unknown skill {skill!r}: this memory knows {', '.join(self.skills)}")
        return self.skills.index(skill)

    def normalise(self, x: np.ndarray) -> np.ndarray:
        """Raw observations (..., D) in the network's normalised units (the cue channels left out)."""
        return (np.asarray(x, np.float64) - self.observed.mean) / self.observed.std

    def courses(self, course: Course, steps: int) -> np.ndarray:
        """(K, steps, D) normalised: each skill's offline recall from its own start (its mean first
        observation) and cue ("recalled"), or its demonstrations' mean course ("mean")."""
        if course == "mean":
            return self.normalise(self.means[:, np.minimum(np.arange(steps), self.means.shape[1] - 1)])
        if course != "recalled":
            raise ValueError(f"course must be 'recalled' or 'mean', got {course!r}")
        cue = with_cue(self.means[:, :1], np.arange(len(self.skills)), len(self.skills))
        return self.model.normaliser.normalise(self.model.recall(cue, steps))[..., : self.width].astype(np.float64)

    def residuals(self, sequences: np.ndarray, courses: np.ndarray, terms: Sequence[str] = TERMS) -> dict[str, np.ndarray]:
        """Raw episodes' (N, T, D) residuals per term against every skill (N, K, T, D), normalised."""
        x = self.normalise(sequences)
        n, steps, _ = x.shape
        k = len(self.skills)
        out = {}
        if "course" in terms:
            out["course"] = x[:, None] - courses[None, :, np.minimum(np.arange(steps), courses.shape[1] - 1)]
        if "dynamics" in terms:
            cued = with_cue(np.repeat(np.asarray(sequences, np.float64), k, axis=0), np.tile(np.arange(k), n), k)
            errors = self.model.errors(cued, "online")[..., : self.width]
            out["dynamics"] = errors.reshape(n, k, steps, -1).astype(np.float64)
        return out

    def calibrate(self, precision: np.ndarray, precision_skills: Labels, threshold: np.ndarray,
                  threshold_skills: Labels, threshold_lengths: np.ndarray | None = None,
                  scoring: SkillScoring = SkillScoring(), fprs: tuple[float, ...] = SCORING.fprs, *,
                  cross_fit: OutOfFold | None = None) -> SkillCalibration:
        """Spreads per skill on one set of normal episodes (raw, with their skills), episode
        thresholds on another, their peaks taken over each episode's own steps (``threshold_lengths``;
        None: every step), the steps scored as ``scoring`` says (`SkillScoring`). With ``cross_fit`` (the
        demonstrations the memory learnt and fold memories, `OutOfFold`) and fewer than 99
        threshold episodes, the fold memories' peaks on the folds they left out join the threshold
        episodes' (cross-fitting: a 1 % threshold on fewer than 99 peaks is their highest). On the
        kitting data, five folds by run, it flagged <= 2 % of normal segments on six splits where
        the held-out rule flagged up to 9 %, at the cost of up to half the anomalies detected
        (docs/kitting.md, "Round 2"): give it whenever the demonstrations are at hand.

        """
        scoring.check()
        for skill in {*map(str, precision_skills), *map(str, threshold_skills)}:
            self.index(skill)
        if cross_fit is not None:
            check_alike(cross_fit.demonstrations, threshold)
        cal = self._spreads(precision, precision_skills, scoring)
        lengths = np.full(len(threshold), np.asarray(threshold).shape[1]) if threshold_lengths is None else threshold_lengths
        pooled = [self._episode_energies(cal, threshold, threshold_skills, lengths)]
        if cross_fit is not None and len(threshold) < conformal_minimum(min(fprs)):
            for k, memory in enumerate(cross_fit.memories):
                # the fold's episodes of a skill the fold memory learnt: of one it never saw, none
                out = (cross_fit.fold == k) & np.isin(cross_fit.labels, cross_fit.labels[cross_fit.fold != k])
                if not out.any():
                    continue
                pooled.append(memory._episode_energies(memory._spreads(precision, precision_skills, scoring),
                                                       cross_fit.demonstrations[out], cross_fit.labels[out],
                                                       cross_fit.lengths[out]))
                cal.out_of_fold_episodes += int(out.sum())
        told, told_skill = (np.concatenate(parts) for parts in zip(*((p.told, p.skills) for p in pooled)))
        if scoring.scaled:
            cal.scales = skill_scales(told, told_skill, len(self.skills))
        inferred = np.concatenate([p.inferred_peaks(cal) for p in pooled])
        for fpr in fprs:
            cal.inferred[fpr] = conformal_episode_threshold(inferred, fpr)
            pooled = conformal_episode_threshold(told, fpr)
            cal.told[fpr] = np.array([conformal_episode_threshold(told[told_skill == k], fpr)
                                      if (told_skill == k).sum() >= 1 / fpr - 1 else pooled
                                      for k in range(len(self.skills))])
        self.calibration = cal
        return cal

    def _spreads(self, precision: np.ndarray, precision_skills: Sequence[str], scoring: SkillScoring) -> SkillCalibration:
        """A calibration without thresholds: the courses and each term's spreads per skill."""
        needed = tuple(dict.fromkeys((*scoring.terms, *scoring.recognised_by)))  # every term used gets its spreads
        courses = self.courses(scoring.course, np.asarray(precision).shape[1])
        floor = SCORING.spread_floor(self.model.rate_hz)
        residuals = self.residuals(precision, courses, needed)
        tails = dict(scoring.tails)
        own = np.array([self.index(str(s)) for s in precision_skills])
        spreads = {}
        for t in needed:
            spread = replace(SkillSpreads.estimate(residuals[t], precision_skills, self.skills, floor), nu=tails.get(t))
            if t in scoring.correlated:  # each episode's residual against its own skill, over that skill's spread
                whitened = residuals[t][np.arange(len(own)), own] / spread.spread[own]
                spread = replace(spread, precision=error_precision(whitened, np.ones(whitened.shape[1:])))
            spreads[t] = spread
        return SkillCalibration(scoring.terms, courses, spreads, scoring.forgetting, scoring.rule, scoring.recognised_by)

    def _episode_energies(self, cal: SkillCalibration, sequences: np.ndarray, skills: Labels,
                          lengths: np.ndarray) -> EpisodeEnergies:
        """Raw episodes' energies not told and peaks told their ``skills``, over their own steps."""
        told = np.array([self.index(str(s)) for s in skills])
        steps = np.arange(np.asarray(sequences).shape[1])
        energies, norm, evidence = cal.scored(self.residuals(sequences, cal.courses, tuple(cal.spreads)), steps)
        inferred, after = infer(energies, norm, cal.forgetting, cal.rule, evidence)
        return EpisodeEnergies(inferred, most_probable_before(after),
                               segment_peaks(energies[np.arange(len(told)), told], lengths), told, lengths)

    def score(self, sequences: np.ndarray, told: Sequence[str] | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Raw episodes' (N, T, D) fault energies (N, T) and posteriors after each step (N, K, T):
        not told (``told`` None) as a session infers them, or each told its skill."""
        cal = self._calibrated()
        steps = np.arange(np.asarray(sequences).shape[1])
        energies, norm, evidence = cal.scored(self.residuals(sequences, cal.courses, tuple(cal.spreads)), steps)
        if told is None:
            inferred, after = infer(energies, norm, cal.forgetting, cal.rule, evidence)
            return cal.in_units(inferred, most_probable_before(after)), after
        index = np.array([self.index(str(s)) for s in told])
        posterior = np.zeros(energies.shape)
        posterior[np.arange(len(index)), index] = 1.0
        return energies[np.arange(len(index)), index], posterior

    def _calibrated(self) -> SkillCalibration:
        if self.calibration is None:
            raise ValueError("the skill memory is not calibrated: SkillMemory.calibrate first")
        return self.calibration

    def session(self, skill: str | None = None, fpr: float = SCORING.default_fpr) -> "SkillSession":
        """One episode scored step by step (`models.skill_session`), told ``skill`` or not."""
        from neural_asm.models.skill_session import SkillSession  # it builds on this module

        return SkillSession(self, skill, fpr)

    def check(self, observation: Sequence[float] | np.ndarray | Mapping[str, float]) -> np.ndarray:
        """An observation (a vector in channel order, or every channel's value by name) as a
        vector, or a ValueError naming what is wrong: before it is queued for a session's step."""
        names = self.channel_names
        if isinstance(observation, Mapping):
            missing, unknown = [n for n in names if n not in observation], sorted(set(observation) - set(names))
            if missing or unknown:
                raise ValueError(f"channels: missing {missing}, unknown {unknown}; expected {list(names)}")
            observation = [observation[n] for n in names]
        raw = np.asarray(observation, np.float64)
        if raw.shape != (self.width,) or not np.isfinite(raw).all():
            raise ValueError(f"observation: expected {self.width} finite values ({', '.join(names)}), "
                             f"got {raw.shape[0] if raw.ndim == 1 else f'shape {raw.shape}'} values")
        return raw
