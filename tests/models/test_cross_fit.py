"""Cross-fitted thresholds: folds that keep a group whole, out-of-fold energies that owe nothing to
the demonstration they score, and the calibration that pools them with the held-out episodes'."""

import numpy as np
import pytest

from neural_asm import SkillMemory
from neural_asm.models.config import FAST
from neural_asm.models.cross_fit import CrossFit, group_folds, out_of_fold_energies
from neural_asm.models.synthetic import make_skills, split

TINY = FAST.with_(hidden_size=16, epochs=20)


@pytest.fixture(scope="module")
def fitted():
    demos, held = split(make_skills(n_skills=2, repetitions=10, steps=12, channels=4, seed=5), 3)
    return SkillMemory.fit(demos, preset=TINY, progress=False), demos, held


def test_folds_keep_each_group_whole_and_deal_groups_evenly():
    runs = np.array([f"2018y06m13d{h:02d}" for h in (1, 1, 2, 3, 3, 3, 4, 5, 6, 7)])
    fold = group_folds(runs, 3, seed=0)
    for r in set(runs):
        assert len(set(fold[runs == r])) == 1  # one run, one fold
    per_fold = np.bincount([fold[runs == r][0] for r in sorted(set(runs))], minlength=3)
    assert sorted(per_fold.tolist()) == [2, 2, 3]  # 7 runs over 3 folds
    assert not np.array_equal(group_folds(np.arange(40), 4, seed=0), group_folds(np.arange(40), 4, seed=1))


@pytest.mark.parametrize("folds", [1, 4])
def test_folds_need_two_to_as_many_as_groups(folds):
    with pytest.raises(ValueError, match=r"2 <= folds <= the number of groups \(3\)"):
        group_folds(["a", "a", "b", "c"], folds, seed=0)


def test_a_demonstration_is_scored_by_networks_that_never_learnt_it(fitted):
    memory, demos, held = fitted
    memory.calibrate(held)
    fold = group_folds(np.arange(len(demos)), 3, seed=0)
    energies = out_of_fold_energies(memory.model, demos.data, demos.labels, held.data[0::2], None, ("offline",), fold,
                                    progress=False)["offline"]
    changed = demos.data.copy()
    changed[0] += 5.0  # only the networks of the other folds learn this demonstration
    again = out_of_fold_energies(memory.model, changed, demos.labels, held.data[0::2], None, ("offline",), fold,
                                 progress=False)["offline"]
    same_fold = fold == fold[0]
    same_fold[0] = False
    np.testing.assert_array_equal(again[same_fold], energies[same_fold])
    assert not np.allclose(again[fold != fold[0]], energies[fold != fold[0]])
    assert again[0].max() > 10 * energies[0].max()  # the changed one, scored by a network that never saw it


def test_calibrate_sets_the_thresholds_on_the_held_out_and_out_of_fold_peaks(fitted):
    memory, demos, held = fitted
    crossing = CrossFit(demos.data, demos.labels, folds=3)
    report = memory.calibrate(held, cross_fit=crossing, progress=False)
    assert report["out_of_fold_episodes"] == len(demos) and report["folds"] == 3
    calibration = memory.model.calibration("offline", 1)
    assert "out-of-fold" in calibration.source
    held_peaks = memory.score(held.data[1::2]).energy.max(axis=1)
    fold = group_folds(np.arange(len(demos)), 3, seed=0)
    precision_labels = [str(label) for label in held.labels[0::2]]
    oof = out_of_fold_energies(memory.model, demos.data, demos.labels, held.data[0::2], precision_labels, ("offline",),
                               fold, progress=False)["offline"]
    # 3 + 14 peaks are fewer than the 99 a 1 % conformal rank needs: the threshold is the pool's highest.
    assert calibration.episode_thresholds[0.01] == pytest.approx(max(held_peaks.max(), oof.max(axis=1).max()))
    assert report["modes"]["online"]["episode_thresholds"]["0.01"] == memory.model.calibration("online", 1) \
        .episode_thresholds[0.01]


def test_cross_fitting_refuses_demonstrations_the_memory_did_not_learn(fitted):
    memory, demos, held = fitted
    with pytest.raises(ValueError, match="trained on 14 sequences, cross-fitting was given 13"):
        memory.calibrate(held, cross_fit=CrossFit(demos.data[1:], folds=3), progress=False)
    with pytest.raises(ValueError, match="the demonstrations have 11 steps, the threshold episodes 12"):
        memory.calibrate(held, cross_fit=CrossFit(demos.data[:, 1:], folds=3), progress=False)
    with pytest.raises(ValueError, match="13 groups for 14 demonstrations"):
        memory.calibrate(held, cross_fit=CrossFit(demos.data, groups=range(13), folds=3), progress=False)
