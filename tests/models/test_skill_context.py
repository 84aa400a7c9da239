"""One memory for every skill told the skill by a cue, or inferring it (models/skill_context.py,
models/skill_posterior.py), on the tests' own kitting-shaped skill courses."""

import numpy as np
import pytest

from kitting_fixtures import skill_curve
from neural_asm.models.config import FAST
from neural_asm.models.skill_calibration import SkillScoring
from neural_asm.models.skill_context import SkillMemory, skills_of
from neural_asm.models.skill_posterior import SkillPosterior, SkillSpreads, infer

SKILLS = (3, 4, 5)
STEPS = 40
NAMES = [f"c{i}" for i in range(6)]


def episodes(n: int, skills: tuple[int, ...], seed: int) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    x = np.stack([skill_curve(s, STEPS, rng) for s in skills for _ in range(n)])
    return x, np.array([str(s) for s in skills for _ in range(n)])


@pytest.fixture(scope="module")
def memory() -> SkillMemory:
    x, y = episodes(10, SKILLS, 0)
    m = SkillMemory.fit(x, NAMES, y, FAST.with_(hidden_size=32, epochs=40))
    m.calibrate(*episodes(5, SKILLS, 1), *episodes(5, SKILLS, 2))
    return m


def test_a_memory_told_the_skill_flags_a_run_that_follows_another_skills_course(memory):
    x, y = episodes(3, SKILLS, 3)
    threshold = memory.calibration.told[0.01]
    own, _ = memory.score(x, told=y)
    assert (own.max(axis=1) <= threshold[[memory.index(s) for s in y]]).mean() >= 0.8  # its own skill: normal
    other, _ = memory.score(x[y == "3"], told=["4"] * 3)  # skill 3's course, told skill 4
    assert (other.max(axis=1) > threshold[memory.index("4")]).all()


def test_not_told_the_posterior_settles_on_the_right_skill(memory):
    x, y = episodes(3, SKILLS, 4)
    energies, posterior = memory.score(x)
    assert [memory.skills[k] for k in posterior[:, :, -1].argmax(axis=1)] == list(y)
    assert (posterior[:, :, -1].max(axis=1) > 0.9).all()
    assert (energies.max(axis=1) <= memory.calibration.inferred[0.01]).mean() >= 0.8


def test_not_told_a_run_that_follows_no_skills_course_is_flagged(memory):
    x, _ = episodes(3, SKILLS, 5)
    between = (x[:3] + x[3:6]) / 2  # half skill 3, half skill 4: no skill's course
    between[:, :, 4] += 8.0  # and a gripper at a level no skill holds
    energies, _ = memory.score(between)
    assert (energies.max(axis=1) > memory.calibration.inferred[0.01]).all()


def test_a_session_answers_as_the_whole_episode_is_scored(memory):
    x, y = episodes(1, SKILLS, 6)
    for told in (None, "4"):
        energies, posterior = memory.score(x[1:2], told=None if told is None else [told])
        session = memory.session(told)
        steps = [session.step(v) for v in x[1]]
        np.testing.assert_allclose([s.energy for s in steps], energies[0], rtol=1e-3, atol=1e-3)  # float32 relaxations batched differently
        assert steps[-1].skill == (told or "4") and steps[-1].fault == (steps[-1].energy > steps[-1].threshold)
        assert steps[-1].probability == pytest.approx(posterior[0, memory.index(steps[-1].skill), -1])


def test_a_skill_the_memory_does_not_know_is_refused(memory):
    with pytest.raises(ValueError, match="unknown skill '9'.*3, 4, 5"):
        memory.session("9")
    with pytest.raises(ValueError, match="unknown skill '9'"):
        memory.score(episodes(1, (3,), 7)[0], told=["9"])


def test_a_model_trained_without_skills_has_none():
    from neural_asm.models.asm import NeuralASM

    x, _ = episodes(3, (3,), 8)
    model = NeuralASM.fit(x, NAMES, FAST.with_(hidden_size=8, epochs=2), progress=False)
    assert skills_of(model) == ()
    with pytest.raises(ValueError, match="trained with skill cues"):
        SkillMemory(model, np.zeros((0, 6)))


def test_the_posterior_forgets_so_it_can_recognise_again():
    energies = np.zeros((1, 2, 40))
    energies[0, 1, :25] = 9.0  # skill 0 explains the first 25 steps, skill 1 the last 15
    energies[0, 0, 25:] = 9.0
    _, after = infer(energies, np.zeros((2, 40)), forgetting=0.01)
    assert after[0, 0, 24] > 0.99 and after[0, 1, -1] > 0.99
    _, stuck = infer(energies, np.zeros((2, 40)), forgetting=0.0)
    assert stuck[0, 0, 24] > 0.99 and stuck[0, 1, -1] < 0.5  # without forgetting it cannot turn in time


def test_the_surprise_is_the_plausible_skills_energy():
    posterior = SkillPosterior(1, 2)
    posterior.log_p = np.log(np.array([[1 - 1e-9, 1e-9]]))
    energy = posterior.energy(np.array([[3.0, 0.0]]), np.zeros(2))
    assert energy[0] == pytest.approx(3.0, abs=0.1)  # skill 1 would explain it, but is not plausible


def test_spreads_borrow_from_every_skill_where_a_skill_has_few_episodes():
    residuals = np.zeros((3, 2, 1, 1))
    residuals[:2, 0] = 1.0  # two episodes of skill a, off by 1 from a's expectation
    residuals[2, 1] = 3.0  # one of b, off by 3
    spreads = SkillSpreads.estimate(residuals, ["a", "a", "b"], ("a", "b"), floor=0.01, prior_episodes=2)
    pooled = (1 + 1 + 9) / 3
    assert spreads.spread[0, 0, 0] == pytest.approx(np.sqrt((2 + 2 * pooled) / 4))
    assert spreads.spread[1, 0, 0] == pytest.approx(np.sqrt((9 + 2 * pooled) / 3))
    with pytest.raises(ValueError, match=r"skill\(s\) \['c'\]"):
        SkillSpreads.estimate(residuals, ["a", "a", "c"], ("a", "b"), floor=0.01)


def test_the_likelihood_template_picks_each_steps_skill_by_its_own_course_and_spreads():
    from neural_asm.rivals.templates import LikelihoodTemplate

    x, y = episodes(10, SKILLS, 9)
    template = LikelihoodTemplate().fit(x, y, [])
    test, truth = episodes(2, SKILLS, 10)
    picked = np.array(template.skill_names)[template.picks(test)]
    assert (picked[:, 5:] == truth[:, None]).all()  # told nothing, it names each episode's skill
    np.testing.assert_allclose(template.expected(test, np.full(len(test), "3"))[:, 5:],
                               template.expected(test, truth)[:, 5:])  # and ignores the skill it is given


def test_the_skill_can_be_recognised_by_the_course_alone_while_both_terms_are_scored(memory):
    x, _ = episodes(1, SKILLS, 11)
    calibrating = (*episodes(5, SKILLS, 1), *episodes(5, SKILLS, 2))
    try:
        memory.calibrate(*calibrating, scoring=SkillScoring(terms=("course",)))
        _, by_course = memory.score(x)
        memory.calibrate(*calibrating, scoring=SkillScoring(recognised_by=("course",)))
        _, posterior = memory.score(x)
        both, _ = memory.score(x, told=["3", "4", "5"])  # scored by both terms: at least the course's energy
        np.testing.assert_allclose(posterior, by_course)  # the dynamics term does not move the posterior
        assert (both >= memory.calibration.spreads["course"].energy(
            memory.residuals(x, memory.calibration.courses, ("course",))["course"], np.arange(STEPS))[
            np.arange(3), [0, 1, 2]] - 1e-9).all()
    finally:
        memory.calibrate(*calibrating)


def test_a_student_t_term_weighs_residuals_by_the_ts_log_likelihood():
    from scipy import stats

    spreads = SkillSpreads(("a",), np.full((1, 1, 1), 2.0), nu=4.0)
    scale = 2.0 * np.sqrt(2 / 4)  # the t's scale of the same variance as the spread
    residuals = np.array([0.5, 3.0, 30.0]).reshape(3, 1, 1, 1)
    energy = spreads.energy(residuals, np.array([0]))[:, 0, 0]
    log_pdf = stats.t.logpdf([0.5, 3.0, 30.0], df=4, scale=scale)
    np.testing.assert_allclose(energy - energy[0], -2 * (log_pdf - log_pdf[0]))  # -2 log-likelihood up to a constant
    gaussian = SkillSpreads(("a",), np.full((1, 1, 1), 2.0)).energy(residuals, np.array([0]))[:, 0, 0]
    assert energy[2] - energy[1] < (gaussian[2] - gaussian[1]) / 10  # a far step adds about its log, not its square
    assert spreads.log_normaliser(np.array([0]))[0, 0] == pytest.approx(2 * np.log(scale))
    with pytest.raises(ValueError, match="degrees of freedom must be > 2"):
        SkillSpreads(("a",), np.ones((1, 1, 1)), nu=2.0)


@pytest.mark.parametrize("nu", [None, 4.0])
def test_spreads_picked_at_a_step_are_their_definitions(nu):
    """The served step reads each skill's scales and log normalisers from tables kept once; they
    are the definitions' values to the last bit, for rows given as indices or a slice and for
    steps past the last (which hold the last step's spreads)."""
    rng = np.random.default_rng(0)
    spread = rng.uniform(0.1, 2.0, (7, 5, 3))
    spreads = SkillSpreads(tuple("abcdefg"), spread, nu)
    residuals = rng.normal(0, 1, (2, 4, 3, 3))  # (N, R, S, D)
    steps = np.array([0, 4, 9])  # 9: past the last step
    for rows, picked in ((np.array([6, 1, 1, 3]), spread[[6, 1, 1, 3]]), (slice(2, 6), spread[2:6])):
        definition = picked[:, np.minimum(steps, 4)]
        scale = definition if nu is None else definition * np.sqrt((nu - 2) / nu)
        z2 = (residuals / scale) ** 2
        energy = z2.sum(axis=-1) if nu is None else (nu + 1) * np.log1p(z2 / nu).sum(axis=-1)
        np.testing.assert_array_equal(spreads.at(steps, rows), definition)
        np.testing.assert_array_equal(spreads.scale(steps, rows), scale)
        np.testing.assert_array_equal(spreads.log_normaliser(steps, rows), 2 * np.log(scale).sum(axis=-1))
        np.testing.assert_array_equal(spreads.energy(residuals, steps, rows), energy)
        for i, step in enumerate(steps.tolist()):  # one step given as an int (a served step's): the same entries
            np.testing.assert_array_equal(spreads.at(step, rows), definition[:, i: i + 1])
            np.testing.assert_array_equal(spreads.log_normaliser(step, rows), 2 * np.log(scale[:, i: i + 1]).sum(axis=-1))
            np.testing.assert_array_equal(spreads.energy(residuals[:, :, i: i + 1], step, rows), energy[:, :, i: i + 1])


def test_the_scored_energies_and_the_evidence_are_the_terms_sums(memory):
    cal = memory.calibration
    x, _ = episodes(1, SKILLS, 8)
    steps = np.arange(x.shape[1])
    residuals = memory.residuals(x, cal.courses, tuple(cal.spreads))
    energies, norm, evidence = cal.scored(residuals, steps)
    assert cal.terms == ("course", "dynamics") and cal.recognised_by == ("course",)  # the defaults
    course, dynamics = cal.spreads["course"], cal.spreads["dynamics"]
    np.testing.assert_array_equal(energies, course.energy(residuals["course"], steps)
                                  + dynamics.energy(residuals["dynamics"], steps))
    np.testing.assert_array_equal(norm, course.log_normaliser(steps) + dynamics.log_normaliser(steps))
    np.testing.assert_array_equal(evidence[0], course.energy(residuals["course"], steps))
    np.testing.assert_array_equal(evidence[1], course.log_normaliser(steps))


def test_the_dynamics_term_is_held_to_a_student_t_by_default(memory):
    calibrating = (*episodes(5, SKILLS, 1), *episodes(5, SKILLS, 2))
    x, _ = episodes(1, SKILLS, 12)
    try:
        cal = memory.calibrate(*calibrating)
        assert cal.spreads["dynamics"].nu == 4.0 and cal.spreads["course"].nu is None
        t_energy, _ = memory.score(x, told=["3", "4", "5"])
        gaussian = memory.calibrate(*calibrating, scoring=SkillScoring(tails=()))
        assert gaussian.spreads["dynamics"].nu is None
        np.testing.assert_allclose(gaussian.spreads["dynamics"].spread, cal.spreads["dynamics"].spread)  # same RMS
        g_energy, _ = memory.score(x, told=["3", "4", "5"])
        assert not np.allclose(t_energy, g_energy)
        with pytest.raises(ValueError, match="terms must be among"):
            memory.calibrate(*calibrating, scoring=SkillScoring(tails=(("speed", 4.0),)))
    finally:
        memory.calibrate(*calibrating)


def test_cross_fitted_thresholds_pool_the_demonstrations_out_of_fold_peaks(memory):
    from neural_asm.models.calibration import conformal_episode_threshold
    from neural_asm.models.skill_context import OutOfFold

    demos, labels = episodes(10, SKILLS, 0)  # what the memory learnt
    precision, (few, few_labels) = episodes(5, SKILLS, 1), episodes(2, SKILLS, 2)  # 6 threshold episodes: < 1 / 0.1 - 1
    course_only = dict(scoring=SkillScoring(terms=("course",), recognised_by=()), fprs=(0.1,))
    out_of_fold = OutOfFold.fit(memory, demos, labels, folds=2, fold_memory=lambda k, x, y: memory.fold(x, y, False))
    for k, fold_memory in enumerate(out_of_fold.memories):  # each fold's course: the other fold's mean
        for s in SKILLS:
            inside = (out_of_fold.fold != k) & (labels == str(s))
            np.testing.assert_allclose(fold_memory.means[fold_memory.index(str(s))], demos[inside].mean(axis=0))
    # fold memories that are the memory itself: the pool is its own peaks on both sets
    in_sample = OutOfFold(demos, labels, out_of_fold.lengths, out_of_fold.fold, (memory, memory))
    try:
        assert memory.calibrate(*precision, few, few_labels, **course_only).out_of_fold_episodes == 0
        cal = memory.calibrate(*precision, few, few_labels, **course_only, cross_fit=in_sample)
        assert cal.out_of_fold_episodes == 30
        pool = np.r_[memory.score(few)[0].max(axis=1), memory.score(demos)[0].max(axis=1)]
        assert cal.inferred[0.1] == pytest.approx(conformal_episode_threshold(pool, 0.1))
        told = np.r_[memory.score(few, told=few_labels)[0].max(axis=1), memory.score(demos, told=labels)[0].max(axis=1)]
        skills = np.r_[few_labels, labels]
        for s in SKILLS:  # 12 pooled peaks a skill, >= 1 / 0.1 - 1: each skill its own threshold
            expected = conformal_episode_threshold(told[skills == str(s)], 0.1)
            assert cal.told[0.1][memory.index(str(s))] == pytest.approx(expected)
        crossed = memory.calibrate(*precision, few, few_labels, **course_only, cross_fit=out_of_fold)
        assert crossed.out_of_fold_episodes == 30 and crossed.inferred[0.1] != cal.inferred[0.1]
        enough = episodes(4, SKILLS, 2)  # 12 threshold episodes: cross-fitting is not needed
        assert memory.calibrate(*precision, *enough, **course_only, cross_fit=out_of_fold).out_of_fold_episodes == 0
    finally:
        memory.calibrate(*precision, *episodes(5, SKILLS, 2))


def test_a_fold_without_a_skill_scores_none_of_its_episodes(memory):
    from neural_asm.models.skill_context import OutOfFold

    demos, labels = episodes(4, SKILLS, 0)
    # every skill-5 demonstration in one run; skills 3 and 4 in three runs that each hold both
    runs = np.where(labels == "5", "run-a", np.array(["run-b", "run-c", "run-d"])[np.arange(len(labels)) % 3])
    out_of_fold = OutOfFold.fit(memory, demos, labels, groups=runs, folds=2,
                                fold_memory=lambda k, x, y: memory.fold(x, y, False))
    alone = out_of_fold.fold[labels == "5"][0]  # the fold of the run that holds every skill-5 demonstration
    fold_memory = out_of_fold.memories[alone]
    five = memory.index("5")
    np.testing.assert_array_equal(fold_memory.means[five], memory.means[five])  # the skill it never saw keeps its course
    precision, few = episodes(5, SKILLS, 2), episodes(1, SKILLS, 3)
    try:
        cal = memory.calibrate(*precision, *few, scoring=SkillScoring(("course",), "mean", (), 0.0),
                               fprs=(0.1,), cross_fit=out_of_fold)
        assert cal.out_of_fold_episodes == len(labels) - (labels == "5").sum()
    finally:
        memory.calibrate(*precision, *episodes(5, SKILLS, 2))


def test_not_told_a_step_is_scored_by_the_skill_most_probable_before_it_by_default(memory):
    x, _ = episodes(1, SKILLS, 13)
    calibrating = (*episodes(5, SKILLS, 1), *episodes(5, SKILLS, 2))
    try:
        for scoring in (SkillScoring(), SkillScoring(scaled=True)):  # each skill's energy in its own units: an option
            cal = memory.calibrate(*calibrating, scoring=scoring)
            energies, posterior = memory.score(x)
            each = np.stack([memory.score(x, told=[str(s)] * len(x))[0] for s in SKILLS], axis=1)  # (N, K, T)
            before = posterior[:, :, :-1].argmax(axis=1)  # the most probable skill after step t - 1
            expected = np.take_along_axis(each[:, :, 1:], before[:, None], axis=1)[:, 0]
            scales = np.ones(len(SKILLS)) if cal.scales is None else cal.scales
            assert (cal.scales is None) == (not scoring.scaled)
            np.testing.assert_allclose(energies[:, 1:], expected / scales[before], rtol=1e-6)
    finally:
        memory.calibrate(*calibrating)


def test_each_skills_scale_is_the_median_of_its_threshold_episodes_peaks_told_it(memory, tmp_path):
    from neural_asm.models import checkpoint

    threshold, labels = episodes(5, SKILLS, 2)  # the fixture's threshold episodes
    told, _ = memory.score(threshold, told=labels)
    scaled = SkillScoring(scaled=True)
    one_each = episodes(5, SKILLS, 1) + (threshold[::5][:2], labels[::5][:2])  # skills 3 and 4 one episode each, 5 none
    try:
        cal = memory.calibrate(*episodes(5, SKILLS, 1), threshold, labels, scoring=scaled)
        for skill in SKILLS:
            peaks = told[labels == str(skill)].max(axis=1)
            assert cal.scales[memory.index(str(skill))] == pytest.approx(np.median(peaks))
        _, loaded = checkpoint.load_memory(checkpoint.save(memory, tmp_path / "m.safetensors"))
        np.testing.assert_array_equal(loaded.calibration.scales, cal.scales)
        np.testing.assert_array_equal(loaded.score(threshold[:3])[0], memory.score(threshold[:3])[0])
        few = memory.calibrate(*one_each, scoring=scaled, fprs=(0.5,))
        assert (few.scales == few.scales[0]).all()  # fewer than 3 episodes: every skill takes the pooled median
    finally:
        memory.calibrate(*episodes(5, SKILLS, 1), *episodes(5, SKILLS, 2))


def test_correlated_channels_are_weighed_together():
    rng = np.random.default_rng(0)
    common = rng.standard_normal((400, 1, 1))
    z = np.concatenate([common, common + 0.1 * rng.standard_normal((400, 1, 1)), rng.standard_normal((400, 1, 1))],
                       axis=2)  # channels 0 and 1 move together, channel 2 alone
    from neural_asm.models.calibration import error_precision

    spreads = SkillSpreads(("a",), np.ones((1, 1, 3)), precision=error_precision(z, np.ones((1, 3))))
    plain = SkillSpreads(("a",), np.ones((1, 1, 3)))
    together, apart = np.array([[[1.0, 1.0, 0.0]]]), np.array([[[1.0, -1.0, 0.0]]])
    assert spreads.energy(together, np.arange(1))[0, 0] < 0.7 * plain.energy(together, np.arange(1))[0, 0]
    assert spreads.energy(apart, np.arange(1))[0, 0] > 10 * plain.energy(apart, np.arange(1))[0, 0]
    with pytest.raises(ValueError, match="not both"):
        SkillSpreads(("a",), np.ones((1, 1, 3)), nu=4.0, precision=np.eye(3)[None])


def test_a_correlated_course_is_kept_by_the_checkpoint_and_a_student_t_term_cannot_be_correlated(memory, tmp_path):
    from neural_asm.models import checkpoint

    precision, threshold = episodes(5, SKILLS, 1), episodes(5, SKILLS, 2)
    try:
        with pytest.raises(ValueError, match=r"\['dynamics'\] held to a Student-t"):
            memory.calibrate(*precision, *threshold, scoring=SkillScoring(correlated=("dynamics",)))
        cal = memory.calibrate(*precision, *threshold, scoring=SkillScoring(correlated=("course",)))
        matrices = cal.spreads["course"].precision
        assert matrices.shape == (STEPS, len(NAMES), len(NAMES)) and cal.spreads["dynamics"].precision is None
        _, loaded = checkpoint.load_memory(checkpoint.save(memory, tmp_path / "m.safetensors"))
        np.testing.assert_array_equal(loaded.calibration.spreads["course"].precision, matrices)
        x, _ = episodes(1, SKILLS, 3)
        np.testing.assert_array_equal(loaded.score(x)[0], memory.score(x)[0])
        plain = memory.calibrate(*precision, *threshold)
        assert not np.allclose(memory.score(x)[0], loaded.score(x)[0])  # the weighing changes the energies
        assert plain.spreads["course"].precision is None
    finally:
        memory.calibrate(*precision, *episodes(5, SKILLS, 2))
