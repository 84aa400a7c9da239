"""The plan probe's models: a per-step map of the cue, causal, and the residual's weight."""

import numpy as np

from lab.plan_probe import PlanOneStep, plan_features
from neural_asm.rivals.one_step import TemplateResidualOneStep


MAPS = np.random.default_rng(7).normal(size=(8, 3, 3))


def _planned(rng, n=40):
    """Episodes whose every step is its own linear map of the first observation (a plan set by the cue),
    with a slow wobble that only the last steps tell."""
    cue = rng.normal(size=(n, MAPS.shape[1]))
    maps = MAPS
    x = np.einsum("nd,tde->nte", cue, maps)
    x[:, 0] = cue
    return x + 0.01 * rng.normal(size=x.shape).cumsum(axis=1)


def test_features_hold_the_cue_in_the_predicted_steps_block(rng):
    x = rng.normal(size=(2, 5, 3))
    f = plan_features(x, steps=5, lags=2, plan=True)
    assert f.shape == (2, 4, 2 * 3 + 5 * 4)
    cue_blocks = f[:, :, 6:].reshape(2, 4, 5, 4)
    for t in range(4):  # predicting step t + 1: only block t + 1 holds [x_0, 1]
        assert np.allclose(cue_blocks[:, t, t + 1], np.c_[x[:, 0], np.ones(2)])
        assert not np.delete(cue_blocks[:, t], t + 1, axis=1).any()


def test_the_plan_term_learns_a_cue_set_plan_that_the_last_steps_alone_cannot(rng):
    x = _planned(rng)
    skills = np.repeat(["a", "b"], 20)
    test = _planned(np.random.default_rng(1))
    errors = {}
    for plan in (False, True):
        detector = PlanOneStep(plan=plan).fit(x, skills, [])
        errors[plan] = ((detector.expected(test, skills)[:, 1:] - test[:, 1:]) ** 2).mean()
    assert errors[True] < 0.05 * errors[False]


def test_expectations_are_causal(rng):
    x = _planned(rng)
    skills = np.repeat(["a", "b"], 20)
    detector = PlanOneStep(plan=True).fit(x, skills, [])
    changed = x.copy()
    changed[:, 5:] += 10.0
    assert np.allclose(detector.expected(x, skills)[:, :6], detector.expected(changed, skills)[:, :6])
    assert np.allclose(detector.expected(x[:, :4], skills), detector.expected(x, skills)[:, :4])


def test_a_residual_weight_of_zero_is_the_template_alone(rng):
    x = _planned(rng)
    skills = np.repeat(["a", "b"], 20)
    alone = TemplateResidualOneStep(residual_weight=0.0).fit(x, skills, [0, 1])
    full = TemplateResidualOneStep().fit(x, skills, [0, 1])
    template = alone.template.expected(x, skills)
    assert np.allclose(alone.expected(x, skills), template)
    assert not np.allclose(full.expected(x, skills), template)


def test_skill_recognition_reads_the_skill_from_the_first_observation_only(rng):
    from types import SimpleNamespace

    from lab.plan_probe import skill_recognition
    from neural_asm.models.normaliser import Normaliser

    def episodes(n, apart):
        labels = np.repeat(["a", "b"], n // 2)
        x = rng.normal(size=(n, 6, 3))
        x[:, 0, 0] += apart * (labels == "b")
        x[:, 1:, 1] += 5.0 * (labels == "b")[:, None]  # later steps tell, the first does not
        return SimpleNamespace(data=x, labels=labels)

    for apart, lowest, highest in ((6.0, 0.95, 1.0), (0.0, 0.25, 0.75)):
        bench = SimpleNamespace(demos=episodes(60, apart), test=episodes(200, apart))
        assert lowest <= skill_recognition(bench, Normaliser.fit(bench.demos.data)) <= highest
