"""The product's skill memory on the kitting segments (`models.skill_context`): one network for
every skill, told each demonstration's skill by a cue, with each skill's mean course and spreads,
scored not told (a posterior over the skills) and told (each segment's skill), with the defaults
of `SkillScoring` and thresholds cross-fitted as `SkillMemory.calibrate` cross-fits them when
given the demonstrations (`OutOfFold`, folds by run: the benchmark's `group_folds`).

Beside it, the rival ``template_likelihood``: each skill's mean course held to its own spreads,
the most probable skill step by step, not told; scored through the same `SkillMemory` with the
course term alone (its network unused), its threshold the served one from the held-out peaks, as
every rival's, and beside it cross-fitted as the memory's (fold templates: each fold's mean courses).
"""

from __future__ import annotations

import numpy as np

from neural_asm.experiments.kitting.config import KittingConfig
from neural_asm.experiments.kitting.data import COLUMNS, Segments, kitting_mapping
from neural_asm.experiments.kitting.methods import RATE_HZ, Scored, Sets
from neural_asm.models.skill_calibration import SkillScoring
from neural_asm.models.skill_context import OutOfFold, SkillMemory

# The report's likelihood template (docs/kitting.md, "A memory that knows each skill's course").
TEMPLATE_LIKELIHOOD = SkillScoring(terms=("course",), course="mean", recognised_by=(), forgetting=0.0,
                                   rule="most_probable", tails=(), scaled=False)


def fit_skill_memory(train: Segments, config: KittingConfig, seed: int) -> SkillMemory:
    """The one network told the skill by a cue, trained on the training runs' normal segments."""
    return SkillMemory.fit(train.data, tuple(COLUMNS), train.skills,
                           config.network.with_(seed=seed, plan_memory=False), rate_hz=RATE_HZ,
                           provenance={"benchmark": "kitting", "seed": seed, "mapping": kitting_mapping().to_dict()})


def out_of_fold(memory: SkillMemory, train: Segments, config: KittingConfig, network: bool = True) -> OutOfFold:
    """Fold memories, each trained as ``memory`` was without one fold of the training runs (without
    ``network``: ``memory``'s network with each fold's mean courses, all a template needs)."""
    folds = min(config.threshold_folds, len(set(train.runs.tolist())))
    return OutOfFold.fit(memory, train.data, train.skills, train.lengths, train.runs, folds, config.split_seed,
                         fold_memory=lambda k, x, y: memory.fold(x, y, network=network))


def _scored(memory: SkillMemory, test: Segments, fprs: tuple[float, ...]) -> tuple[Scored, Scored]:
    """The calibrated memory's test energies and thresholds, not told and told each segment's skill."""
    cal = memory.calibration
    assert cal is not None, "SkillMemory.calibrate first"
    n, rows = len(test), np.array([memory.index(str(s)) for s in test.skills])
    inferred, _ = memory.score(test.data)
    told, _ = memory.score(test.data, told=test.skills)
    return (Scored(inferred, {f: np.full(n, cal.inferred[f]) for f in fprs}),
            Scored(told, {f: cal.told[f][rows] for f in fprs}))


def score_skill_memory(memory: SkillMemory, sets: Sets, config: KittingConfig) -> dict[str, Scored]:
    """The memory calibrated as a user's `calibrate` with the demonstrations does (spreads on the
    precision half, thresholds on the threshold half and the training runs' out-of-fold peaks),
    scored not told (``skill_memory``) and told (``skill_memory_told``)."""
    p, t = sets.precision, sets.threshold
    memory.calibrate(p.data, p.skills, t.data, t.skills, t.lengths, fprs=config.fprs,
                     cross_fit=out_of_fold(memory, sets.train, config))
    inferred, told = _scored(memory, sets.test, config.fprs)
    return {"skill_memory": inferred, "skill_memory_told": told}


def score_template_likelihood(memory: SkillMemory, sets: Sets, config: KittingConfig) -> dict[str, Scored]:
    """The rival: the training runs' mean courses and held-out spreads, not told, scored by the
    most probable skill's course term (``memory``'s network is not used); its threshold from the
    held-out peaks as every rival's (``template_likelihood``), and cross-fitted as the memory's from
    fold templates (``template_likelihood_cross_fitted``)."""
    template = SkillMemory(memory.model, memory.means)
    p, t = sets.precision, sets.threshold
    out = {}
    for name, crossing in (("template_likelihood", None),
                           ("template_likelihood_cross_fitted", out_of_fold(template, sets.train, config, False))):
        template.calibrate(p.data, p.skills, t.data, t.skills, t.lengths, TEMPLATE_LIKELIHOOD, config.fprs,
                           cross_fit=crossing)
        out[name] = _scored(template, sets.test, config.fprs)[0]
    return out
