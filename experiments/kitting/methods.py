"""The monitors compared on the kitting segments, each reduced to an energy per step and the
served episode thresholds (`models.calibration`): the skill memory told or not told the skill
and the likelihood template (`skill_methods`), the one Neural ASM for every skill (not told the
skill; with the served threshold, or one cross-fitted on the training runs' out-of-fold peaks),
per-skill networks, templates told the skill or picking the nearest one, the linear one-step
predictor, an LSTM predictor trained by BPTT, and two trivial detectors.

Every learned or template method is calibrated as the product calibrates a model: precisions on
one half of the held-out normal runs (`models.calibration.estimate`), episode thresholds on the
other half (split-conformal on their peak energies, `conformal_episode_threshold`), each peak
taken over a segment's own steps (not the samples held to pad it to the model's length).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np
from torch import nn

from neural_asm.experiments.kitting.config import KittingConfig
from neural_asm.experiments.kitting.data import COLUMNS, PERIOD_S, Segments, kitting_mapping
from neural_asm.models.asm import NeuralASM
from neural_asm.models.calibration import Calibration, Weighting, conformal_episode_threshold, estimate
from neural_asm.models.config import SCORING
from neural_asm.models.cross_fit import group_folds, out_of_fold_energies
from neural_asm.models.normaliser import Normaliser
from neural_asm.rivals.one_step import LinearOneStep
from neural_asm.rivals.sequence import GRUOneStep, RecurrentConfig
from neural_asm.rivals.templates import PerSkillZScore

RATE_HZ = 1 / PERIOD_S
FORCE = 0  # the force norm's channel


@dataclass(frozen=True)
class MethodInfo:
    name: str
    label: str
    is_neural_asm: bool
    told_skill: bool
    learned: bool  # depends on a training seed
    trivial: bool = False
    cross_fitted: bool = False  # its thresholds also from out-of-fold peaks of the training runs


METHODS = (
    MethodInfo("skill_memory", "the skill memory: one Neural ASM told each demonstration's skill by a cue, each skill's "
               "mean course and dynamics, not told (a posterior over the skills); thresholds cross-fitted", True, False,
               True, cross_fitted=True),
    MethodInfo("skill_memory_told", "the same skill memory told each segment's skill", True, True, True,
               cross_fitted=True),
    MethodInfo("nasm_one", "one Neural ASM for every skill, skill recognised (offline recall)", True, False, True),
    MethodInfo("nasm_one_cross_fitted", "one Neural ASM (offline), its threshold also from out-of-fold peaks of the "
               "training runs (cross-fitted)", True, False, True, cross_fitted=True),
    MethodInfo("nasm_one_online", "one Neural ASM, skill recognised (online recall)", True, False, True),
    MethodInfo("nasm_one_pooled", "one Neural ASM, one calibration for every skill (the 20 Hz default)", True, False, True),
    MethodInfo("nasm_one_plan", "one Neural ASM, plan recall: the skill recognised at the cue", True, False, True),
    MethodInfo("nasm_one_told", "oracle: one Neural ASM (offline), its calibration told each segment's skill", True,
               True, True),
    MethodInfo("nasm_per_skill", "a Neural ASM per skill, told the skill", True, True, True),
    MethodInfo("template_told", "per-skill z-score template, told the skill", False, True, False),
    MethodInfo("template_told_cross_fitted", "the same template, its threshold cross-fitted as the skill memory's "
               "(fold templates of the training runs)", False, True, False, cross_fitted=True),
    MethodInfo("template_nearest", "template picking the nearest skill itself", False, False, False),
    MethodInfo("template_likelihood", "rival: each skill's mean course and own spreads, the most probable skill step "
               "by step (not told)", False, False, False),
    MethodInfo("template_likelihood_cross_fitted", "the same rival, its threshold cross-fitted as the skill memory's "
               "(fold templates of the training runs)", False, False, False, cross_fitted=True),
    MethodInfo("linear_one_step", "linear one-step predictor (ridge), told the skill", False, True, True),
    MethodInfo("lstm", "LSTM one-step predictor (BPTT), told the skill", False, True, True),
    MethodInfo("length", "trivial: segment length so far", False, False, False, True),
    MethodInfo("peak_force", "trivial: peak force norm", False, False, False, True),
)
INFO = {m.name: m for m in METHODS}


@dataclass
class Scored:
    """A method's energies (N, T) of the test segments and each segment's threshold per rate."""

    energies: np.ndarray
    thresholds: dict[float, np.ndarray]  # fpr -> (N,)


@dataclass
class Sets:
    train: Segments
    precision: Segments  # held-out normal runs: precisions
    threshold: Segments  # held-out normal runs: thresholds
    test: Segments


def segment_peaks(energies: np.ndarray, lengths: np.ndarray) -> np.ndarray:
    """Each segment's peak energy over its own steps (not the samples that pad it)."""
    return np.array([e[:n].max() for e, n in zip(energies, lengths)])


def network_peaks(model: NeuralASM, segs: Segments, mode: str) -> np.ndarray:
    """Each segment's peak energy over its own steps under the model's calibration of ``mode``."""
    return segment_peaks(model.score(segs.data, mode).energy, segs.lengths)


def served_thresholds(energies: np.ndarray, lengths: np.ndarray, fprs: tuple[float, ...]) -> dict[float, float]:
    """Episode thresholds of normal segments' peak energies over their own steps (the served rule's)."""
    peaks = segment_peaks(energies, lengths)
    return {f: conformal_episode_threshold(peaks, f) for f in fprs}


def _broadcast(thresholds: dict[float, float], n: int) -> dict[float, np.ndarray]:
    return {f: np.full(n, t) for f, t in thresholds.items()}


def error_calibration(errors: Callable[[Segments], np.ndarray], precision: Segments) -> Calibration:
    """The product's calibration of a predictor's errors, on the precision half."""
    return estimate("baseline", 1, errors(precision), "held-out normal runs", SCORING.error_covariance,
                    SCORING.spread_floor(RATE_HZ), False, precision.skills)


def calibrated_energies(errors: Callable[[Segments], np.ndarray], sets: Sets, fprs: tuple[float, ...]) -> Scored:
    """Energies of the test segments under the product's calibration of a predictor's errors."""
    cal = error_calibration(errors, sets.precision)
    thresholds = served_thresholds(cal.energy(errors(sets.threshold)), sets.threshold.lengths, fprs)
    return Scored(cal.energy(errors(sets.test)), _broadcast(thresholds, len(sets.test)))


def fit_network(train: Segments, config: KittingConfig, seed: int) -> NeuralASM:
    """The one network, its provenance naming the mapping its data were read through (what `nasm
    replay` checks logs against before streaming them to it)."""
    return NeuralASM.fit(train.data, tuple(COLUMNS), config.network.with_(seed=seed), progress=False,
                         labels=train.skills, rate_hz=RATE_HZ).noted(
        {"benchmark": "kitting", "seed": seed, "mapping": kitting_mapping().to_dict()})


def calibrate_served(model: NeuralASM, sets: Sets, mode: str, centred: bool, fprs: tuple[float, ...]) -> Calibration:
    """Calibrate the network as served: precisions (and each skill's mean error, when ``centred``)
    on one half of the held-out runs, episode thresholds on the other half's own steps."""
    cal = model.calibrate(sets.precision.data, sets.threshold.data, mode, 1, SCORING.fprs, "held-out normal runs",
                          labels=sets.precision.skills, weighting=Weighting(centred=centred))
    energies = model.score(sets.threshold.data, mode).energy
    cal.episode_thresholds.update(served_thresholds(energies, sets.threshold.lengths, SCORING.fprs))
    return cal


def score_network(model: NeuralASM, sets: Sets, mode: str, centred: bool, fprs: tuple[float, ...]) -> Scored:
    cal = calibrate_served(model, sets, mode, centred, fprs)
    energies = model.score(sets.test.data, mode).energy
    return Scored(energies, _broadcast({f: cal.episode_thresholds[f] for f in fprs}, len(sets.test)))


def training_folds(train: Segments, config: KittingConfig) -> np.ndarray:
    """Each training segment's fold for cross-fitting: ``config.threshold_folds`` folds by run."""
    return group_folds(train.runs, min(config.threshold_folds, len(set(train.runs.tolist()))), config.split_seed)


def training_energies_out_of_fold(model: NeuralASM, sets: Sets, config: KittingConfig) -> np.ndarray:
    """(N, T) energies of the training segments, each under a network fitted as ``model`` was
    without its run's fold (`training_folds`), calibrated as it is served: the product's
    cross-fitting (`models.cross_fit`, what `nasm calibrate --cross-fit` runs)."""
    mode = config.recall_mode
    return out_of_fold_energies(model, sets.train.data, sets.train.skills, sets.precision.data,
                                list(sets.precision.skills), (mode,), training_folds(sets.train, config),
                                progress=False)[mode]


def out_of_fold_peaks(model: NeuralASM, sets: Sets, config: KittingConfig) -> np.ndarray:
    """Each training segment's peak energy out of fold (`training_energies_out_of_fold`)."""
    return segment_peaks(training_energies_out_of_fold(model, sets, config), sets.train.lengths)


def cross_fitted(served: Scored, held_out: np.ndarray, out_of_fold: np.ndarray, fprs: tuple[float, ...]) -> Scored:
    """``served``'s energies with episode thresholds from the held-out peaks and the training runs'
    out-of-fold peaks. With the 36-40 held-out peaks alone a 1 % threshold is their highest and
    promises nothing; with ~260 it is a split-conformal quantile (docs/kitting.md, "Thresholds from
    more normal runs")."""
    pool = np.concatenate([held_out, out_of_fold])
    return Scored(served.energies, _broadcast({f: conformal_episode_threshold(pool, f) for f in fprs},
                                              len(served.energies)))


def score_cross_fitted(model: NeuralASM, served: Scored, sets: Sets, config: KittingConfig) -> Scored:
    """The served network's energies (``served``, from `score_network` with its served calibration)
    with its threshold cross-fitted (`cross_fitted`)."""
    return cross_fitted(served, network_peaks(model, sets.threshold, config.recall_mode),
                        out_of_fold_peaks(model, sets, config), config.fprs)


def score_told(model: NeuralASM, sets: Sets, mode: str, fprs: tuple[float, ...]) -> Scored:
    """The oracle beside the served calibration (`calibrate_served`, centred, already done): each
    segment's errors less its own skill's mean errors instead of the recognised skill's, thresholds
    likewise; what recognising the skill costs the one network."""
    cal = model.calibration(mode, 1)
    assert cal is not None and cal.error_mean is not None, "calibrate_served(centred=True) first"
    energies = cal.energy(model.errors(sets.threshold.data, mode), sets.threshold.skills)
    thresholds = served_thresholds(energies, sets.threshold.lengths, fprs)
    return Scored(cal.energy(model.errors(sets.test.data, mode), sets.test.skills), _broadcast(thresholds, len(sets.test)))


def score_per_skill(sets: Sets, config: KittingConfig, seed: int, skills: tuple[str, ...]) -> Scored:
    """A network per skill, each calibrated on its skill's held-out runs; a test segment scored by its skill's."""
    n, steps = len(sets.test), sets.test.data.shape[1]
    energies, thresholds = np.full((n, steps), np.nan), {f: np.full(n, np.nan) for f in config.fprs}
    for skill in skills:
        pick = {name: getattr(sets, name).take(getattr(sets, name).skills == skill)
                for name in ("train", "precision", "threshold")}
        model = fit_network(pick["train"], config, seed)
        one = Sets(pick["train"], pick["precision"], pick["threshold"], sets.test.take(sets.test.skills == skill))
        scored = score_network(model, one, config.recall_mode, False, config.fprs)
        rows = sets.test.skills == skill
        energies[rows] = scored.energies
        for f in config.fprs:
            thresholds[f][rows] = scored.thresholds[f]
    return Scored(energies, thresholds)


def nearest_template(means: dict[str, np.ndarray], x: np.ndarray) -> np.ndarray:
    """(N, T, D) each step's expectation from the skill whose template fits the steps before it
    best (at the first step: the first observation), as the network's recognition is cued."""
    names = sorted(means)
    m = np.stack([means[s][: x.shape[1]] for s in names])  # (S, T, D)
    misfit = ((x[:, None] - m[None]) ** 2).sum(-1)  # (N, S, T)
    before = np.concatenate([misfit[..., :1], np.cumsum(misfit, axis=2)[..., :-1]], axis=2)
    pick = before.argmin(axis=1)  # (N, T)
    return m[pick, np.arange(x.shape[1])[None]]


class LSTMOneStep(GRUOneStep):
    """The published method's family: an LSTM reads x[0..t] (and the skill) and predicts x[t+1]."""

    name = "lstm_one_step"
    label = "LSTM one-step predictor (BPTT)"

    def _build(self) -> nn.Module:
        net = super()._build()
        net.gru = nn.LSTM(self.dims + len(self.skill_names), self.config.hidden_size, batch_first=True)
        return net


def errors_of(normaliser: Normaliser, predictor) -> Callable[[Segments], np.ndarray]:
    """A predictor's errors on segments, in the normalised units it learnt in, told each one's skill."""
    return lambda s: normaliser.normalise(s.data) - predictor.expected(normaliser.normalise(s.data), s.skills)


def fit_template(train: Segments, seed: int) -> tuple[Normaliser, PerSkillZScore]:
    """The per-skill z-score template of normalised training segments, with its normaliser."""
    normaliser = Normaliser.fit(train.data)
    return normaliser, PerSkillZScore().fit(normaliser.normalise(train.data), train.skills, [], seed)


def score_template_told_cross_fitted(served: Scored, sets: Sets, config: KittingConfig, seed: int) -> Scored:
    """The told template's energies (``served``) with its threshold cross-fitted as the skill
    memory's is: each training segment's peak under a template fitted without its run's fold
    (`training_folds`) and calibrated as served, beside the held-out peaks. A template needs two
    demonstrations of a skill: a fold's segments of a skill with fewer in the fold's training part
    (of the few-demonstration skills) add no peak."""
    errors = errors_of(*fit_template(sets.train, seed))
    held_out = segment_peaks(error_calibration(errors, sets.precision).energy(errors(sets.threshold)),
                             sets.threshold.lengths)
    fold, peaks = training_folds(sets.train, config), [held_out]
    for k in np.unique(fold):
        part = sets.train.take(fold != k)
        names, counts = np.unique(part.skills, return_counts=True)
        modelled = names[counts >= 2]
        fold_errors = errors_of(*fit_template(part.take(np.isin(part.skills, modelled)), seed))
        left_out = sets.train.take((fold == k) & np.isin(sets.train.skills, modelled))
        precision = sets.precision.take(np.isin(sets.precision.skills, modelled))
        peaks.append(segment_peaks(error_calibration(fold_errors, precision).energy(fold_errors(left_out)),
                                   left_out.lengths))
    return cross_fitted(served, peaks[0], np.concatenate(peaks[1:]), config.fprs)


def score_baselines(sets: Sets, config: KittingConfig, seed: int, learned_only: bool) -> dict[str, Scored]:
    """The templates and predictors (those that depend on ``seed`` only, with ``learned_only``)."""
    normaliser, template = fit_template(sets.train, seed)
    train_x = normaliser.normalise(sets.train.data)
    out: dict[str, Scored] = {}
    if not learned_only:
        out["template_told"] = calibrated_energies(errors_of(normaliser, template), sets, config.fprs)
        out["template_told_cross_fitted"] = score_template_told_cross_fitted(out["template_told"], sets, config, seed)
        out["template_nearest"] = calibrated_energies(
            lambda s: normaliser.normalise(s.data) - nearest_template(template.means, normaliser.normalise(s.data)),
            sets, config.fprs)
        out["length"] = _trivial(lambda s: np.broadcast_to(np.arange(s.data.shape[1]) * PERIOD_S, s.data.shape[:2]),
                                 sets, config.fprs)
        out["peak_force"] = _trivial(lambda s: s.data[..., FORCE], sets, config.fprs)
    linear = LinearOneStep().fit(train_x, sets.train.skills, [], seed)
    out["linear_one_step"] = calibrated_energies(errors_of(normaliser, linear), sets, config.fprs)
    lstm = LSTMOneStep(RecurrentConfig(max_epochs=config.lstm_epochs, patience=15)).fit(train_x, sets.train.skills, [], seed)
    out["lstm"] = calibrated_energies(errors_of(normaliser, lstm), sets, config.fprs)
    return out


def _trivial(value: Callable[[Segments], np.ndarray], sets: Sets, fprs: tuple[float, ...]) -> Scored:
    thresholds = served_thresholds(value(sets.threshold), sets.threshold.lengths, fprs)
    return Scored(np.array(value(sets.test), float), _broadcast(thresholds, len(sets.test)))
