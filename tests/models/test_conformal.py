"""Conformal thresholds: the false-alarm guarantee on many calibration draws, and input checks."""

import math

import numpy as np
import pytest
from scipy import stats

from neural_asm.models.calibration import Thresholds
from neural_asm.models.config import FAST, SCORING
from neural_asm.models.conformal import (
    TimeVaryingThreshold,
    binomial_interval,
    episode_threshold,
    mcnemar_exact,
)


@pytest.mark.slow  # many calibration draws
def test_episode_threshold_keeps_the_guarantee_over_calibration_draws(rng):
    # n=100, alpha=0.1: rank ceil(101*0.9)=91, so the exact flag rate is 1-91/101=0.0990,
    # inside [alpha - 1/(n+1), alpha]. The flag rate of each threshold is exact (normal tail).
    n, alpha, draws = 100, 0.1, 20000
    cal = rng.standard_normal((draws, n))
    rates = np.array([stats.norm.sf(episode_threshold(c, alpha)) for c in cal])
    assert alpha - 1 / (n + 1) <= rates.mean() <= alpha
    assert rates.mean() == pytest.approx(1 - 91 / 101, abs=1e-3)


def test_episode_threshold_holds_with_tied_scores(rng):
    n, alpha, draws = 60, 0.05, 5000
    cal = rng.poisson(3.0, (draws, n)).astype(float)
    rates = np.array([stats.poisson.sf(episode_threshold(c, alpha), 3.0) for c in cal])
    assert rates.mean() <= alpha


def test_empirical_flag_rate_on_fresh_normals(rng):
    cal, fresh = rng.gamma(2.0, size=500), rng.gamma(2.0, size=200_000)
    rate = (fresh > episode_threshold(cal, 0.01)).mean()
    low, high = binomial_interval(int((fresh > episode_threshold(cal, 0.01)).sum()), len(fresh))
    assert low <= rate <= high
    assert rate < 0.03  # one draw: the guarantee is on average, but not this far off


def test_too_few_calibration_scores_never_flag():
    assert episode_threshold(np.arange(10.0), 0.05) == math.inf  # rank ceil(11*0.95)=11 > 10
    assert episode_threshold(np.arange(19.0), 0.05) == 18.0  # rank 19 of 19


@pytest.mark.parametrize(
    "scores, alpha, match",
    [
        (np.array([1.0, np.nan]), 0.1, "NaN"),
        (np.array([1.0, np.inf]), 0.1, "NaN or infinite"),
        (np.ones((3, 2)), 0.1, "1-D"),
        (np.array([]), 0.1, "empty"),
        (np.ones(5), 0.0, "alpha"),
        (np.ones(5), 1.0, "alpha"),
        (np.ones(5), float("nan"), "alpha"),
    ],
)
def test_episode_threshold_rejects_bad_input(scores, alpha, match):
    with pytest.raises(ValueError, match=match):
        episode_threshold(scores, alpha)


def _episodes(rng, n, sigma):
    """Energies (n, T) of independent steps: sigma_t^2 times chi-square(3)."""
    return sigma**2 * rng.chisquare(3, (n, len(sigma)))


@pytest.mark.slow  # many calibration draws
def test_time_varying_threshold_keeps_the_episode_guarantee(rng):
    sigma = np.linspace(0.2, 3.0, 12)
    alpha, n_cal, draws = 0.1, 100, 2000
    rates = []
    for _ in range(draws):
        tv = TimeVaryingThreshold().fit(_episodes(rng, 200, sigma), _episodes(rng, n_cal, sigma), alpha)
        # Exact flag probability of a fresh episode: 1 - prod_t P(E_t <= threshold_t).
        rates.append(1 - np.prod(stats.chi2.cdf(tv.thresholds / sigma**2, 3)))
    assert alpha - 1 / (n_cal + 1) <= np.mean(rates) <= alpha
    # The thresholds follow the normal energy: last step's is far above the first's.
    assert tv.thresholds[-1] / tv.thresholds[0] > 50


def test_time_varying_flags_and_first_crossing():
    tv = TimeVaryingThreshold(scale_quantile=1.0).fit(np.ones((5, 4)), np.ones((30, 4)), 0.1)
    assert np.allclose(tv.thresholds, 1.0)
    energies = np.array([[0.5, 2.0, 0.5, 2.0], [0.5, 0.5, 0.5, 0.5], [3.0, 0.5, 0.5, 0.5]])
    assert tv.flags(energies).tolist() == [[False, True, False, True], [False] * 4, [True] + [False] * 3]
    assert tv.first_crossing(energies).tolist() == [1, -1, 0]
    assert tv.first_crossing(energies, from_step=2).tolist() == [3, -1, -1]
    assert tv.flags(energies[:, :2]).shape == (3, 2)  # a running episode


def test_time_varying_floor_keeps_a_silent_step_from_dividing_by_zero():
    scale = np.ones((50, 3))
    scale[:, 1] = 0.0
    tv = TimeVaryingThreshold().fit(scale, np.ones((30, 3)), 0.1)
    assert np.all(np.isfinite(tv.thresholds)) and tv.thresholds[1] > 0


def test_time_varying_rejects_bad_input():
    with pytest.raises(RuntimeError, match="not fitted"):
        TimeVaryingThreshold().thresholds
    with pytest.raises(ValueError, match="steps"):
        TimeVaryingThreshold().fit(np.ones((5, 4)), np.ones((30, 3)), 0.1)
    with pytest.raises(ValueError, match="2-D"):
        TimeVaryingThreshold().fit(np.ones(5), np.ones((30, 3)), 0.1)
    with pytest.raises(ValueError, match="NaN"):
        TimeVaryingThreshold().fit(np.full((5, 3), np.nan), np.ones((30, 3)), 0.1)
    tv = TimeVaryingThreshold().fit(np.ones((5, 4)), np.ones((30, 4)), 0.1)
    with pytest.raises(ValueError, match="steps"):
        tv.flags(np.ones((2, 5)))
    with pytest.raises(ValueError, match="from_step"):
        tv.first_crossing(np.ones((2, 4)), from_step=-1)


def test_binomial_interval_is_clopper_pearson():
    low, high = binomial_interval(0, 100)
    assert low == 0.0 and high == pytest.approx(1 - 0.025 ** (1 / 100))  # closed form at k=0
    low, high = binomial_interval(50, 100)
    assert low < 0.5 < high and high - low < 0.21
    with pytest.raises(ValueError, match="k must"):
        binomial_interval(5, 4)
    with pytest.raises(ValueError, match="n must"):
        binomial_interval(0, 0)


def test_mcnemar_exact():
    assert mcnemar_exact(0, 0) == 1.0
    assert mcnemar_exact(5, 5) == 1.0
    assert mcnemar_exact(10, 0) == pytest.approx(2 * 0.5**10)
    assert mcnemar_exact(0, 10) == mcnemar_exact(10, 0)
    with pytest.raises(ValueError, match="b_only"):
        mcnemar_exact(3, -1)


@pytest.mark.slow  # many calibration draws
def test_the_served_episode_threshold_is_the_conformal_rank(rng):
    # 150 calibration episodes at 1 %: rank ceil(151 * 0.99) = 150, the highest peak (np.quantile's
    # "higher" method gives the 149th, which flags 2/151 of normal episodes on average, not 1/151).
    energies = rng.gamma(2.0, size=(150, 15))
    peaks = np.sort(energies.max(axis=1))
    assert Thresholds.of(energies, 0.01).episode == peaks[-1]
    assert Thresholds.of(energies[:120], 0.05).episode == np.sort(energies[:120].max(axis=1))[114]  # ceil(121*.95)
    # over calibration draws the flag rate of fresh normal episodes stays within alpha
    n, alpha = 150, 0.01
    cal = rng.standard_normal((20000, n, 1))
    rates = np.array([stats.norm.sf(Thresholds.of(c, alpha).episode) for c in cal])
    assert alpha - 1 / (n + 1) <= rates.mean() <= alpha


def test_too_few_episodes_for_the_guarantee_serve_the_highest_peak():
    energies = np.arange(40.0).reshape(20, 2)  # 20 episodes: a 1 % guarantee needs 99
    assert Thresholds.of(energies, 0.01).episode == 39.0


def test_the_spread_floor_scales_with_the_observation_period():
    assert SCORING.spread_floor(2.0) == pytest.approx(SCORING.error_std_floor)
    assert SCORING.spread_floor(40.0) == pytest.approx(SCORING.error_std_floor / 20)
    with pytest.raises(ValueError, match="rate_hz"):
        SCORING.spread_floor(0.0)


def test_models_are_served_offline_at_the_papers_rate_and_online_faster():
    assert [SCORING.served_mode(r) for r in (0.5, 2.0, 2.5, 20.0, 40.0)] == \
        ["offline", "offline", "online", "online", "online"]
    with pytest.raises(ValueError, match="rate_hz"):
        SCORING.served_mode(0.0)


def test_a_model_calibrated_in_one_mode_is_served_in_it():
    from neural_asm.models.asm import NeuralASM

    data = np.random.default_rng(0).standard_normal((6, 5, 3))
    model = NeuralASM.fit(data, ["a", "b", "c"], FAST.with_(hidden_size=8, epochs=2), progress=False, rate_hz=20.0)
    assert model.served_mode == "online"  # not calibrated yet: the rate's
    model.calibrate(data, data, "offline", 1)
    assert model.served_mode == "offline"  # the one mode it can decide in
    model.calibrate(data, data, "online", 1)
    assert model.served_mode == "online"
