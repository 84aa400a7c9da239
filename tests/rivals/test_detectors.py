"""The rivals on small synthetic tasks whose truth is known."""

import numpy as np
import pytest

from neural_asm.models.one_step import RidgeOneStep, delay_embed, fit_one_step
from neural_asm.rivals.base import Detector, Spread
from neural_asm.rivals.one_step import LinearOneStep, TemplateResidualOneStep
from neural_asm.rivals.registry import line_up
from neural_asm.rivals.sequence import LSTMVAE, GRUOneStep, RecurrentConfig
from neural_asm.rivals.statistics import StepStatistics
from neural_asm.rivals.templates import ConditionalTemplate, CueNearestDemos, CueTemplate, NearestDemos, PerSkillZScore

from synthetic_tasks import C, D, T, varied_task

CONTEXT = list(range(C))
SMALL_RNN = RecurrentConfig(hidden_size=32, latent_size=4, max_epochs=150, patience=15, kl_anneal_epochs=20)


def fitted(detector, demos, skills):
    return detector.fit(demos, skills, CONTEXT, seed=0)


def small_detectors():
    """Every detector class, the recurrent ones at a size that trains in seconds."""
    return [d for d in line_up("varied") if not hasattr(d, "config")] + [GRUOneStep(SMALL_RNN), LSTMVAE(SMALL_RNN)]


@pytest.fixture(scope="module")
def task():
    return varied_task(30, seed=0, speed_spread=0.1), varied_task(40, seed=1, speed_spread=0.1)


@pytest.fixture(scope="module")
def detectors(task):
    (demos, skills), _ = task
    return [fitted(d, demos, skills) for d in small_detectors()]


def mse(x, expected):
    return float(((x - expected)[:, 1:] ** 2).mean())


def test_all_detectors_are_distinct_and_follow_the_protocol():
    found = line_up("varied")
    assert len({d.name for d in found}) == len(found) == 10
    assert all(isinstance(d, Detector) and d.label for d in found)


@pytest.mark.slow
def test_shapes_and_causality(detectors, task):
    _, (x, skills) = task
    rng = np.random.default_rng(5)
    for det in detectors:
        expected = det.expected(x, skills)
        assert expected.shape == x.shape and np.all(np.isfinite(expected)), det.name
        for t in (0, 4, T - 2):
            changed = x.copy()
            changed[:, t + 1 :] += rng.standard_normal(changed[:, t + 1 :].shape)
            np.testing.assert_allclose(
                det.expected(changed, skills)[:, : t + 1], expected[:, : t + 1], atol=1e-9, err_msg=det.name
            )
        # A running episode: its first steps only, the same expectation.
        np.testing.assert_allclose(det.expected(x[:, :5], skills), expected[:, :5], atol=1e-9, err_msg=det.name)


def test_conditional_template_far_below_the_per_skill_mean():
    demos, skills = varied_task(40, seed=0)
    x, test_skills = varied_task(60, seed=1)
    mean = mse(x, fitted(PerSkillZScore(), demos, skills).expected(x, test_skills))
    template = fitted(ConditionalTemplate(), demos, skills)
    assert mse(x, template.expected(x, test_skills)) < 0.1 * mean
    assert {t.degree for t in template.templates.values()} == {2}  # the task is quadratic in c
    assert mse(x, fitted(NearestDemos(), demos, skills).expected(x, test_skills)) < 0.5 * mean


def test_without_context_the_templates_are_the_per_skill_mean(task):
    (demos, skills), (x, test_skills) = task
    mean = PerSkillZScore().fit(demos, skills, []).expected(x, test_skills)
    for det in (ConditionalTemplate(), NearestDemos()):
        np.testing.assert_allclose(det.fit(demos, skills, []).expected(x, test_skills), mean, atol=1e-9)


@pytest.mark.slow
def test_one_step_predictors_track_a_random_speed():
    demos, skills = varied_task(40, seed=0, speed_spread=0.4)
    x, test_skills = varied_task(60, seed=1, speed_spread=0.4)
    template = mse(x, fitted(ConditionalTemplate(), demos, skills).expected(x, test_skills))
    for det in (TemplateResidualOneStep(), LinearOneStep(), GRUOneStep(SMALL_RNN)):
        assert mse(x, fitted(det, demos, skills).expected(x, test_skills)) < 0.5 * template, det.name


@pytest.mark.slow
def test_every_detector_errs_more_on_a_perturbed_episode(detectors, task):
    _, (x, skills) = task
    faulty = x.copy()
    faulty[:, 5:, C : C + 3] += 1.5  # three channels jump mid-episode, in normalised units
    for det in detectors:
        normal = ((x - det.expected(x, skills))[:, 5:] ** 2).sum(axis=(1, 2))
        perturbed = ((faulty - det.expected(faulty, skills))[:, 5:] ** 2).sum(axis=(1, 2))
        assert np.mean(perturbed > normal) > 0.95 and np.median(perturbed) > 3 * np.median(normal), det.name


@pytest.mark.slow
def test_recurrent_detectors_are_deterministic_given_the_seed(task):
    (demos, skills), (x, test_skills) = task
    config = RecurrentConfig(hidden_size=16, latent_size=2, max_epochs=30, kl_anneal_epochs=10)
    for cls in (GRUOneStep, LSTMVAE):
        a, b = (cls(config).fit(demos, skills, CONTEXT, seed=3).expected(x, test_skills) for _ in range(2))
        np.testing.assert_array_equal(a, b)


def test_bad_input_is_named(task):
    (demos, skills), (x, test_skills) = task
    det = PerSkillZScore()
    with pytest.raises(RuntimeError, match="not fitted"):
        det.expected(x, test_skills)
    with pytest.raises(ValueError, match="context_channels"):
        det.fit(demos, skills, [D])
    with pytest.raises(ValueError, match="NaN"):
        det.fit(np.where(demos > 2, np.nan, demos), skills, CONTEXT)
    with pytest.raises(ValueError, match="skills must have shape"):
        det.fit(demos, skills[:-1], CONTEXT)
    with pytest.raises(ValueError, match=">= 2 demonstrations"):
        det.fit(demos[:31], skills[:31], CONTEXT)
    det.fit(demos, skills, CONTEXT)
    with pytest.raises(ValueError, match="unknown skills"):
        det.expected(x, np.full(len(x), "stack"))
    with pytest.raises(ValueError, match="channels"):
        det.expected(x[:, :, :-1], test_skills)
    with pytest.raises(ValueError, match="steps"):
        det.expected(np.concatenate([x, x], axis=1), test_skills)


def test_delay_embedding_is_causal_and_keeps_the_current_step_first():
    x = np.random.default_rng(0).standard_normal((3, 6, 4))
    embedded = delay_embed(x, 3)
    assert embedded.shape == (3, 6, 12)
    np.testing.assert_array_equal(embedded[..., :4], x)
    np.testing.assert_array_equal(embedded[:, 4, 4:8], x[:, 3])  # one step back
    np.testing.assert_array_equal(embedded[:, 4, 8:], x[:, 2])  # two steps back
    np.testing.assert_array_equal(embedded[:, 0, 8:], x[:, 0])  # before the start: the first step
    np.testing.assert_array_equal(delay_embed(x, 1), x)


def test_one_step_predictor_reads_two_steps_of_an_oscillator():
    """x[t+1] = 2 cos(w) x[t] - x[t-1]: one step cannot tell the phase's direction, two can."""
    rng = np.random.default_rng(0)
    t = np.arange(T)[None, :, None]
    phase = rng.uniform(0, 2 * np.pi, (60, 1, D))
    x = np.sin(0.7 * t + phase) + 0.01 * rng.standard_normal((60, T, D))
    skills = np.array(["osc"] * 60)
    detector = LinearOneStep().fit(x[:40], skills[:40], [], seed=0)
    assert detector.one_step.lags >= 2
    error = ((detector.expected(x[40:], skills[40:]) - x[40:])[:, 1:] ** 2).mean()
    one_lag = fit_one_step(x[:40], skills[:40], seed=0, lag_choices=(1,))
    one_lag_error = ((one_lag.predict(x[40:], skills[40:]) - x[40:, 1:]) ** 2).mean()
    assert error < 0.2 * one_lag_error


def test_the_whole_cue_tells_the_templates_the_start_posture():
    """A start posture no context channel reports (an offset the whole episode keeps): only the
    templates that read the whole first observation can expect it."""
    rng = np.random.default_rng(5)
    (demos, skills), (test, test_skills) = varied_task(40, seed=2), varied_task(30, seed=3)
    for x in (demos, test):
        x[:, :, C:] += rng.uniform(-1.0, 1.0, (len(x), 1, 1))  # the posture, from step 0 on
    context_only = [fitted(d, demos, skills) for d in (ConditionalTemplate(), NearestDemos())]
    whole_cue = [fitted(d, demos, skills) for d in (CueTemplate(), CueNearestDemos())]
    for narrow, wide in zip(context_only, whole_cue):
        assert mse(test, wide.expected(test, test_skills)) < 0.5 * mse(test, narrow.expected(test, test_skills))


def test_the_paper_line_up_is_the_paper_sweeps_z_scores_and_one_step_predictor():
    """Built from the registry, the paper sweep's rivals expect (and spread) exactly what its
    per-step statistics and its one ridge one-step model (one past step, ridge 0.01, pooled) do."""
    rng = np.random.default_rng(0)
    skills = np.repeat(["a", "b"], 6)
    demos = rng.standard_normal((12, T, D)) + np.where(skills == "a", 2.0, -2.0)[:, None, None]
    x = rng.standard_normal((5, T, D)) + 2.0
    told = np.array(["a", "b", "a", "a", "b"])
    rivals = {r.name: r.fit(demos, skills, []) for r in line_up("paper")}
    assert list(rivals) == ["zscore_pooled", "zscore_per_skill", "classic_asm", "linear_one_step"]
    pooled, library = StepStatistics.fit(demos), StepStatistics.fit(demos, skills)
    np.testing.assert_array_equal(rivals["zscore_pooled"].expected(x, told), pooled.expected(x))
    np.testing.assert_array_equal(rivals["classic_asm"].spread(x, told), library.spread(x))
    by_skill = np.searchsorted(["a", "b"], told)
    np.testing.assert_array_equal(rivals["zscore_per_skill"].spread(x, told), library.stds[by_skill])
    one_step = RidgeOneStep.fit(demos)
    np.testing.assert_allclose(rivals["linear_one_step"].expected(x, told)[:, 1:], one_step.step(x[:, :-1]))
    assert all(isinstance(r, Spread) for name, r in rivals.items() if name != "linear_one_step")
