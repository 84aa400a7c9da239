"""Round 4's probe pools the told peaks exactly as `SkillMemory.calibrate` does."""

from types import SimpleNamespace

import numpy as np
import pytest

from lab.kitting_told_threshold import told_pool
from neural_asm.models.calibration import conformal_episode_threshold
from neural_asm.models.config import FAST
from neural_asm.models.skill_calibration import SkillScoring
from neural_asm.models.skill_context import OutOfFold, SkillMemory


def segments(n: int, rng: np.random.Generator) -> SimpleNamespace:
    skills = np.array(["a", "b"] * n)
    level = np.where(skills == "a", 0.0, 2.0)[:, None, None]
    data = level + np.sin(np.linspace(0, 3, 12))[None, :, None] + 0.1 * rng.standard_normal((2 * n, 12, 2))
    return SimpleNamespace(data=data, skills=skills, lengths=np.full(2 * n, 12))


def test_the_pooled_told_peaks_are_those_calibrate_pools(rng):
    demos, precision, threshold = segments(4, rng), segments(3, rng), segments(1, rng)
    memory = SkillMemory.fit(demos.data, ("x", "y"), demos.skills, FAST.with_(hidden_size=8, epochs=3))
    folds = OutOfFold.fit(memory, demos.data, demos.skills, folds=2, fold_memory=lambda k, x, y: memory.fold(x, y, False))
    scoring = SkillScoring(("course",), "mean", (), 0.0)
    cal = memory.calibrate(precision.data, precision.skills, threshold.data, threshold.skills, threshold.lengths,
                           scoring, (0.1,), cross_fit=folds)
    pool = told_pool(memory, SimpleNamespace(precision=precision, threshold=threshold), folds, scoring)
    assert len(pool) == 2 + 8 and cal.out_of_fold_episodes == 8
    # 5 pooled peaks a skill, fewer than 1 / 0.1 - 1: calibrate gives every skill the pool's threshold
    assert cal.told[0.1] == pytest.approx(np.full(2, conformal_episode_threshold(pool, 0.1)))
