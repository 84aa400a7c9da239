"""Template detectors: each skill's expected trajectory, fixed from the episode's first step.

- ``PerSkillZScore``: the per-skill per-step mean of the demonstrations (classic ASM).
- ``LikelihoodTemplate``: the same means, not told the skill: at each step, the skill most probable
  given the steps before under each skill's own course and spreads.
- ``ConditionalTemplate``: per skill, every step's observation ridge-regressed on the
  context c (linear or quadratic features, chosen by leave-one-out error; a ridge strength
  per step and channel, chosen likewise on the demonstrations only).
- ``NearestDemos``: per skill, the mean of the k demonstrations whose standardised context is
  nearest (k by leave-one-out error).
- ``CueTemplate``, ``CueNearestDemos``: the same two on the whole first observation (the cue
  the Neural ASM gets), so the start posture counts as context too.
- ``StepRidgeTemplate``: per skill, every step a linear function of the context, all steps in one
  ridge regression with one strength: plan recall's input pathway without the network.

Without context channels ``ConditionalTemplate`` and ``NearestDemos`` reduce to the per-skill mean.
"""

from __future__ import annotations

import numpy as np
from sklearn.linear_model import RidgeCV
from sklearn.pipeline import Pipeline, make_pipeline
from sklearn.preprocessing import PolynomialFeatures, StandardScaler

from neural_asm.models.one_step import episode_folds
from neural_asm.models.skill_posterior import SkillSpreads, infer
from neural_asm.rivals.base import DetectorBase
from neural_asm.models.step_maps import apply_maps, input_features, ridge_maps, step_codes

RIDGE_ALPHAS = np.logspace(-3, 4, 15)
NEIGHBOUR_COUNTS = (1, 2, 3, 4, 5, 6, 8, 10, 12, 15, 20, 25, 30, 40)


class PerSkillZScore(DetectorBase):
    name = "per_skill_zscore"
    label = "per-skill z-score (classic ASM)"

    def _fit(self, x: np.ndarray, skills: np.ndarray, seed: int) -> None:
        self.means = {s: x[skills == s].mean(axis=0) for s in self.skill_names}
        self.stds = {s: x[skills == s].std(axis=0) for s in self.skill_names}

    def _expected(self, x: np.ndarray, skills: np.ndarray) -> np.ndarray:
        return np.stack([self.means[s][: x.shape[1]] for s in skills])

    def spread(self, x: np.ndarray, skills: np.ndarray) -> np.ndarray:
        """The true skill's per-step std of the demonstrations (N, T, D): the z-score denominator."""
        return np.stack([self.stds[s][: x.shape[1]] for s in skills])


class LikelihoodTemplate(PerSkillZScore):
    """Each skill's mean course, the skill not told: every step is expected by the skill most
    probable given the steps before it (at the first step, given it), each skill's course held to
    its own spreads per step (its demonstrations' residuals, shrunk towards every skill's:
    `models.skill_posterior`). A step's log-likelihood under a skill counts its spreads, so a
    run that fits no skill's course within that skill's spreads is no skill's normal."""

    name = "template_likelihood"
    label = "per-skill template, the most probable skill by each skill's own course and spreads (not told)"

    def _fit(self, x: np.ndarray, skills: np.ndarray, seed: int) -> None:
        super()._fit(x, skills, seed)
        courses = np.stack([self.means[s] for s in self.skill_names])
        self.spreads = SkillSpreads.estimate(x[:, None] - courses[None], skills, tuple(self.skill_names), floor=1e-3)

    def picks(self, x: np.ndarray) -> np.ndarray:
        """(N, T) the index of the skill whose course expects each step."""
        courses = np.stack([self.means[s][: x.shape[1]] for s in self.skill_names])
        steps = np.arange(x.shape[1])
        energies = self.spreads.energy(x[:, None] - courses[None], steps)
        _, after = infer(energies, self.spreads.log_normaliser(steps), forgetting=0.0, rule="most_probable")
        # the skill most probable before each step (after the first step, for the first)
        return np.concatenate([after[:, :, :1], after[:, :, :-1]], axis=2).argmax(axis=1)

    def _expected(self, x: np.ndarray, skills: np.ndarray) -> np.ndarray:
        courses = np.stack([self.means[s][: x.shape[1]] for s in self.skill_names])
        return courses[self.picks(x), np.arange(x.shape[1])]

    def spread(self, x: np.ndarray, skills: np.ndarray) -> np.ndarray:
        """The picked skill's spread at each step (N, T, D)."""
        return self.spreads.spread[self.picks(x), np.arange(x.shape[1])]


class _SkillRegression:
    """One skill's template: all T*D step values as a ridge regression on context features."""

    def __init__(self, x: np.ndarray, c: np.ndarray) -> None:
        self.shape = x.shape[1:]
        self.mean = x.mean(axis=0)
        self.model: Pipeline | None = None
        self.degree = 0
        if c.shape[1] == 0:
            return
        y = x.reshape(len(x), -1)
        best = np.inf
        for degree in (1, 2):
            model = make_pipeline(
                StandardScaler(),
                PolynomialFeatures(degree, include_bias=False),
                StandardScaler(),
                RidgeCV(alphas=RIDGE_ALPHAS, alpha_per_target=True, store_cv_results=True),
            ).fit(c, y)
            # Leave-one-out squared errors (n, targets, alphas); each target at its best alpha.
            loo = model[-1].cv_results_.mean(axis=0).min(axis=-1).sum()
            if loo < best:
                best, self.model, self.degree = loo, model, degree

    def predict(self, c: np.ndarray) -> np.ndarray:
        if self.model is None:
            return np.broadcast_to(self.mean, (len(c),) + self.shape).copy()
        return self.model.predict(c).reshape((len(c),) + self.shape)


class ConditionalTemplate(DetectorBase):
    name = "conditional_template"
    label = "conditional template (ridge on context)"

    def _fit(self, x: np.ndarray, skills: np.ndarray, seed: int) -> None:
        c = self.context(x)
        self.templates = {s: _SkillRegression(x[skills == s], c[skills == s]) for s in self.skill_names}

    def _expected(self, x: np.ndarray, skills: np.ndarray) -> np.ndarray:
        out = np.empty_like(x)
        c = self.context(x)
        for s in np.unique(skills):
            rows = skills == s
            out[rows] = self.templates[s].predict(c[rows])[:, : x.shape[1]]
        return out

    def cross_fitted_residuals(self, x: np.ndarray, skills: np.ndarray, seed: int) -> np.ndarray:
        """x minus the template of a fit that did not see the episode (K folds by episode).

        In-sample residuals of a regression are smaller than a new episode's; a model of
        the residual trained on them would expect too little.
        """
        c = self.context(x)
        residuals = np.empty_like(x)
        for train, test in episode_folds(skills, seed):
            for s in np.unique(skills[test]):
                fit_rows = train[skills[train] == s]
                rows = test[skills[test] == s]
                residuals[rows] = x[rows] - _SkillRegression(x[fit_rows], c[fit_rows]).predict(c[rows])
        return residuals


class NearestDemos(DetectorBase):
    name = "nearest_demos"
    label = "k-nearest-demonstration template"

    def _fit(self, x: np.ndarray, skills: np.ndarray, seed: int) -> None:
        c = self.context(x)
        self.demos: dict[str, np.ndarray] = {}
        self.contexts: dict[str, np.ndarray] = {}
        self.scalers: dict[str, StandardScaler] = {}
        self.k: dict[str, int] = {}
        for s in self.skill_names:
            xs, cs = x[skills == s], c[skills == s]
            self.scalers[s] = StandardScaler().fit(cs) if cs.shape[1] else None
            self.demos[s] = xs
            self.contexts[s] = self.scalers[s].transform(cs) if cs.shape[1] else cs
            self.k[s] = self._choose_k(xs, self.contexts[s])

    @staticmethod
    def _choose_k(xs: np.ndarray, cs: np.ndarray) -> int:
        """Leave-one-out: each demonstration predicted by its k nearest others."""
        n = len(xs)
        if cs.shape[1] == 0:
            return n
        dist = ((cs[:, None] - cs[None]) ** 2).sum(-1)
        np.fill_diagonal(dist, np.inf)
        order = np.argsort(dist, axis=1, kind="stable")[:, : n - 1]
        candidates = [k for k in NEIGHBOUR_COUNTS if k <= n - 1] + [n - 1]
        errors = [((xs - xs[order[:, :k]].mean(axis=1)) ** 2).mean() for k in candidates]
        return candidates[int(np.argmin(errors))]

    def _expected(self, x: np.ndarray, skills: np.ndarray) -> np.ndarray:
        out = np.empty_like(x)
        c = self.context(x)
        for s in np.unique(skills):
            rows = skills == s
            demos, k = self.demos[s], self.k[s]
            if self.scalers[s] is None:
                out[rows] = demos.mean(axis=0)[: x.shape[1]]
                continue
            query = self.scalers[s].transform(c[rows])
            dist = ((query[:, None] - self.contexts[s][None]) ** 2).sum(-1)
            nearest = np.argsort(dist, axis=1, kind="stable")[:, :k]
            out[rows] = demos[nearest].mean(axis=1)[:, : x.shape[1]]
        return out


class CueTemplate(ConditionalTemplate):
    """The conditional template regressed on the whole cue: the context channels and every other
    channel of the first observation (the start posture the arm's null space carries forward).
    The Neural ASM is cued by that same observation."""

    name = "cue_template"
    label = "conditional template (ridge on the whole first observation)"

    def context(self, x: np.ndarray) -> np.ndarray:
        return x[:, 0, :]


class CueNearestDemos(NearestDemos):
    """The k nearest demonstrations by the whole first observation (context and start posture)."""

    name = "cue_nearest_demos"
    label = "k-nearest-demonstration template (whole first observation)"

    def context(self, x: np.ndarray) -> np.ndarray:
        return x[:, 0, :]


class StepRidgeTemplate(DetectorBase):
    """Per skill, each step's observation a linear function of the context, every step in one ridge
    regression whose single strength generalised cross-validation chooses (``ConditionalTemplate``
    chooses one per step and channel, and a quadratic form where leave-one-out error prefers it).
    It is plan recall's input pathway (models/plan.py) without the network, so the Neural ASM's
    plan recall is measured against its own linear special case."""

    name = "step_ridge_template"
    label = "conditional template (one ridge per skill over every step)"

    def _features(self, x: np.ndarray) -> np.ndarray:
        return input_features(self.context(x)[:, None], step_codes(np.arange(x.shape[1]), self.steps)[None])

    def _fit(self, x: np.ndarray, skills: np.ndarray, seed: int) -> None:
        self.maps = ridge_maps(self._features(x), x, skills, tuple(self.skill_names))

    def _expected(self, x: np.ndarray, skills: np.ndarray) -> np.ndarray:
        return apply_maps(self.maps, self._features(x), np.array([self.skill_names.index(s) for s in skills]))

    def cross_fitted_residuals(self, x: np.ndarray, skills: np.ndarray, seed: int) -> np.ndarray:
        """x minus the template of a fit that did not see the episode (K folds by episode)."""
        residuals = np.empty_like(x)
        for train, test in episode_folds(skills, seed):
            fold = type(self)().fit(x[train], skills[train], self.context_channels.tolist(), seed)
            residuals[test] = x[test] - fold.expected(x[test], skills[test])
        return residuals

