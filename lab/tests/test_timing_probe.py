"""The timing probe: plan recall's linear part told the route and the speed, or inferring the speed."""

import numpy as np

from lab.timing_probe import GRID, TOLD, InferredSpeedPlan, ToldPlan, only, plan_context
from neural_asm.models.normaliser import Normaliser
from neural_asm.rivals.one_step import TemplateResidualOneStep
from neural_asm.rivals.templates import StepRidgeTemplate

STEPS = 12


def _warped(rng, n: int = 40) -> np.ndarray:
    """Episodes of one skill: an arm channel that ramps from 0 to a context-set height at the
    episode's speed (its phase is speed x step), a context channel, noise, then the two told
    channels (route side 0: no post; the speed)."""
    speed = rng.uniform(0.8, 1.2, n)
    height = rng.uniform(1.0, 2.0, n)
    phase = np.minimum(speed[:, None] * np.arange(STEPS)[None] / 6.0, 1.0)
    x = np.zeros((n, STEPS, 3 + len(TOLD)))
    x[..., 0] = height[:, None] * phase
    x[..., 1] = height[:, None]
    x[..., 2] = 0.01 * rng.normal(size=(n, STEPS))
    x[..., 3], x[..., 4] = 0.0, speed[:, None]
    return x


def test_the_context_form_is_the_benchmarks_rival_on_the_other_channels(rng):
    x = _warped(rng)
    x[..., 3] = np.where(rng.uniform(size=len(x)) < 0.5, -1.0, 1.0)[:, None]  # a route told, but not used
    norm = Normaliser.fit(x)
    xn, skills = norm.normalise(x), np.full(len(x), "ramp")
    told = ToldPlan("context", norm).fit(xn, skills, [1])
    rival = TemplateResidualOneStep(template=StepRidgeTemplate).fit(xn[..., :3], skills, [1])
    expected = told.expected(xn, skills)
    np.testing.assert_allclose(expected[..., :3], rival.expected(xn[..., :3], skills), atol=1e-6)
    np.testing.assert_array_equal(expected[..., 3:], xn[..., 3:])  # the told channels, expected exactly


def test_the_forms_add_the_told_values_as_they_say():
    context, route, speed = np.ones((3, 2)), np.array([1.0, -1.0, 0.0]), np.array([0.8, 1.0, 1.2])
    assert plan_context(context, route, speed, "context").shape == (3, 2)
    assert np.array_equal(plan_context(context, route, speed, "route")[:, 2], route)
    assert plan_context(context, route, speed, "speed").shape == (3, 7)
    bilinear = plan_context(context, route, speed, "bilinear").reshape(3, 5, 4)  # basis x [context, route, 1]
    np.testing.assert_allclose(bilinear[..., 2], bilinear[..., 3] * route[:, None])


def test_the_speed_is_told_by_the_motion_once_it_shows(rng):
    """Told each demonstration's speed, the bilinear plan fits the warped ramps; on new episodes
    the speed inferred from the steps before each step is the prior's (1) at the start, and half
    as far from the true one once the ramp has shown it; its plan then expects the ramp as the told one does."""
    x, new = _warped(rng, 60), _warped(rng, 30)
    norm = Normaliser.fit(x)
    xn, skills = norm.normalise(x), np.full(len(x), "ramp")
    inferred = InferredSpeedPlan(norm, name_route=False).fit(xn, skills, [1])
    told = ToldPlan("bilinear", norm).fit(xn, skills, [1])
    nn, new_skills = norm.normalise(new), np.full(len(new), "ramp")
    speeds = inferred.inferred_speeds(nn, new_skills)
    assert np.all(speeds[:, 0] == GRID[np.argmin(np.abs(GRID - 1.0))])
    truth = new[:, 0, -1]
    rms = np.sqrt(((speeds - truth[:, None]) ** 2).mean(axis=0))
    assert rms[4] < 0.5 * rms[0]
    late = slice(5, None)
    error_inferred = ((nn - inferred.expected(nn, new_skills))[:, late, 0] ** 2).mean()
    error_told = ((nn - told.expected(nn, new_skills))[:, late, 0] ** 2).mean()
    error_context = ((nn - ToldPlan("context", norm).fit(xn, skills, [1]).expected(nn, new_skills))[:, late, 0] ** 2).mean()
    assert error_inferred < 2 * error_told < error_context


def test_the_aligned_speed_explains_timing_away_but_not_a_detour(rng):
    """Chosen with each step, the speed fits the ramps' timing better than the one chosen before
    it; a departure no speed's plan makes (an offset once every ramp has risen) stays whole."""
    x, new = _warped(rng, 60), _warped(rng, 30)
    norm = Normaliser.fit(x)
    xn, skills = norm.normalise(x), np.full(len(x), "ramp")
    aligned = InferredSpeedPlan(norm, name_route=False, aligned=True).fit(xn, skills, [1])
    inferred = InferredSpeedPlan(norm, name_route=False).fit(xn, skills, [1])
    nn, new_skills = norm.normalise(new), np.full(len(new), "ramp")
    rising = slice(1, 6)
    error_aligned = ((nn - aligned.expected(nn, new_skills))[:, rising, 0] ** 2).mean()
    error_inferred = ((nn - inferred.expected(nn, new_skills))[:, rising, 0] ** 2).mean()
    assert error_aligned < error_inferred
    offset = 0.5  # normalised units, on the risen ramp's last steps
    detoured = nn.copy()
    detoured[:, 9:, 0] += offset
    residual = (detoured - aligned.expected(detoured, new_skills))[:, 9, 0]
    assert residual.mean() > 0.8 * offset


def test_the_route_is_named_from_the_episodes_around_a_post_only(rng):
    """The route side read back from normalised channels is exactly 0 for a skill without a post,
    so the namer learns the side from the episodes that have one and names no other."""
    x = _warped(rng, 80)
    around = np.arange(len(x)) < 40
    side = np.where(rng.uniform(size=len(x)) < 0.5, -1.0, 1.0)
    x[..., 1] = np.where(around, side, 0.0)[:, None] + 0.05 * rng.normal(size=(len(x), 1))  # the context shows the side
    x[..., 3] = np.where(around, side, 0.0)[:, None]
    norm = Normaliser.fit(x)
    xn, skills = norm.normalise(x), np.where(around, "around", "ramp")
    plan = InferredSpeedPlan(norm, name_route=True).fit(xn, skills, [1])
    told, _ = ToldPlan.told(plan, xn)
    np.testing.assert_array_equal(told, np.where(around, side, 0.0))
    named, _ = plan.told(xn)
    assert np.all(named[~around] == 0.0)
    assert np.mean(np.sign(named[around]) == side[around]) > 0.9


def test_an_expectation_of_some_channels_expects_the_others_exactly(rng):
    x = rng.normal(size=(4, 6, 5))
    zeros = only(lambda x, _skills: np.zeros_like(x), [1, 3])(x, np.full(4, "ramp"))
    np.testing.assert_array_equal(zeros[..., [1, 3]], 0.0)
    np.testing.assert_array_equal(zeros[..., [0, 2, 4]], x[..., [0, 2, 4]])
