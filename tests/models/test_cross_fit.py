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
    with pytest.raises(ValueError, match=r"2 <= folds <= the number of groups \(3 among 4 demonstrations\)"):
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
    assert all("out-of-fold" in memory.model.calibration(mode, 1).source for mode in ("offline", "online"))
    calibration = memory.model.calibration("offline", 1)
    held_peaks = memory.score(held.data[1::2]).energy.max(axis=1)
    fold = group_folds(np.arange(len(demos)), 3, seed=0)
    precision_labels = [str(label) for label in held.labels[0::2]]
    oof = out_of_fold_energies(memory.model, demos.data, demos.labels, held.data[0::2], precision_labels, ("offline",),
                               fold, progress=False)["offline"]
    # 3 + 14 peaks are fewer than the 99 a 1 % conformal rank needs: the threshold is the pool's highest.
    assert calibration.episode_thresholds[0.01] == pytest.approx(max(held_peaks.max(), oof.max(axis=1).max()))
    assert oof.max() > held_peaks.max()  # the pool raised it: fold networks learnt a third less


@pytest.mark.parametrize("crossing, message", [
    (lambda d: CrossFit(d.data[1:], d.labels[1:], folds=3), "trained on \\(14 sequences\\); these 13 are not"),
    (lambda d: CrossFit(d.data + 0.5, d.labels, folds=3), "these 14 are not: their count, channel means or spreads"),
    (lambda d: CrossFit(d.data[:, 1:], d.labels, folds=3), "the demonstrations have 11 steps, the threshold episodes 12"),
    (lambda d: CrossFit(d.data, folds=3), "learnt the skills \\[0, 1\\]: cross-fitting needs each demonstration's skill"),
    (lambda d: CrossFit(d.data, d.labels[:5], folds=3), "5 skill labels for 14 demonstrations"),
    (lambda d: CrossFit(d.data, d.labels, groups=range(13), folds=3), "13 groups for 14 demonstrations"),
])
def test_cross_fitting_refuses_what_it_cannot_use_and_leaves_the_memory_as_it_was(fitted, crossing, message):
    memory, demos, held = fitted
    before = {key: cal.episode_thresholds.copy() for key, cal in memory.model.calibrations.items()}
    with pytest.raises(ValueError, match=message):
        memory.calibrate(held, cross_fit=crossing(demos), progress=False)
    assert {key: cal.episode_thresholds for key, cal in memory.model.calibrations.items()} == before


def test_a_plan_memory_with_too_few_demonstrations_in_a_fold_is_refused_before_training():
    demos, held = split(make_skills(n_skills=2, repetitions=7, steps=8, channels=3, seed=6), 3)  # 4 of each skill
    memory = SkillMemory.fit(demos, preset=TINY.with_(plan_memory=True), progress=False)
    with pytest.raises(ValueError, match=r"fold \d of 4 left out: a plan memory needs at least 3 .* use fewer folds"):
        memory.calibrate(held, cross_fit=CrossFit(demos.data, demos.labels, folds=4), progress=False)


def test_groups_from_where_episodes_were_read():
    from neural_asm.calibrate_cli import episode_groups, grouping
    from neural_asm.models.sequences import EpisodeFacts, Sequences

    origins = ["skill 3/No.0 successful skill from experiment_at_2018y05m19d15H48M03S/a.csv",
               "skill 4/No.1 successful skill from experiment_at_2018y05m19d15H48M03S/b.csv",
               "skill 4/No.1 successful skill from experiment_at_2018y05m20d10H00M00S/c.csv",
               "bag d.mcap, episode 3", "bag d.mcap, episode 4", "runs/t.csv episode 7"]
    facts = tuple(EpisodeFacts(i, origin, 2, 0.0) for i, origin in enumerate(origins))
    seqs = Sequences(np.zeros((6, 2, 1)), np.zeros(6), ("x",), episodes=facts)
    assert episode_groups(seqs, grouping("file")).tolist()[3:] == ["bag d.mcap", "bag d.mcap", "runs/t.csv"]
    baxter = Sequences(np.zeros((3, 2, 1)), np.zeros(3), ("x",), episodes=facts[:3])
    runs = episode_groups(baxter, grouping(r"experiment_at_\w+"))
    assert runs[0] == runs[1] != runs[2]  # one run's skills in one group, though their folders differ
    with pytest.raises(ValueError, match="matches nothing in 'bag d.mcap, episode 3' \\(3 of 6 episodes\\)"):
        episode_groups(seqs, grouping(r"experiment_at_\w+"))
    with pytest.raises(ValueError, match="'episode', 'file' or a regular expression; '\\[' is none"):
        grouping("[")


def test_a_memory_monitors_and_scores_in_its_served_mode_unless_told_another():
    demos = make_skills(n_skills=2, repetitions=6, steps=8, channels=4, seed=2).data
    for rate, served in ((2.0, "offline"), (20.0, "online")):
        memory = SkillMemory.fit(demos, preset=TINY, rate_hz=rate, progress=False)
        assert memory.served_mode == served
        np.testing.assert_array_equal(memory.score(demos).energy, memory.score(demos, served).energy)
        other = "online" if served == "offline" else "offline"
        assert not np.array_equal(memory.score(demos).energy, memory.score(demos, other).energy)
