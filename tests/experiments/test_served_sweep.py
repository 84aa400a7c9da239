"""The served monitor's sweep at any rate: onsets from twins, flags by the service's rule, latency."""

from __future__ import annotations

import copy

import numpy as np
import pytest

from neural_asm.experiments.fault_sweep.rate_figures import write_latency_figure
from neural_asm.experiments.fault_sweep.rate import markdown, spread
from neural_asm.experiments.fault_sweep.served import (Flagged, Onsets, each_ms, flagged, flagged_over_resplits, from_visible,
                                            latency_ms, percentiles_ms, quiet, subsampled)
from neural_asm.models.fault import flag_steps
from neural_asm.models.sequences import Sequences


@pytest.fixture(scope="module")
def calibrated(trained, skills):
    train, test = skills
    model = copy.deepcopy(trained)
    model.calibrate(train.data, test.data, "online", 1)
    return model, test


def test_onsets_pair_by_seed_and_are_the_first_differing_step(skills):
    _, test = skills
    twins = Sequences(test.data, test.labels, test.channel_names, seeds=np.arange(len(test)), rate_hz=40.0)
    changed = test.data.copy()
    changed[0, 7:, 2] += 1.0
    changed[1, 3:, 0] -= 0.5
    episodes = Sequences(changed[:3], test.labels[:3], test.channel_names, seeds=np.array([0, 1, 99]), rate_hz=40.0)
    onsets = Onsets.against(episodes, np.array([3, 1, 5]), twins, twins)
    assert onsets.episodes.seeds.tolist() == [0, 1]  # seed 99 has no twin
    assert onsets.label.tolist() == [3, 1] and onsets.onset_s.tolist() == [7 / 40, 3 / 40]


def ramps() -> tuple[Sequences, Sequences, Sequences]:
    """Locks against twins whose departures cross 3 normal sd at known ticks. Normal spread: 1 on
    every channel of skill "a", 4 on channel 2 of skill "b" (each tick's two normal episodes per
    skill are +-sd apart from a whole-numbered course, so their std is exactly sd)."""
    steps, channels = 20, 4
    course = np.arange(steps)[:, None] * np.arange(1.0, channels + 1)
    sd = {"a": np.ones(channels), "b": np.array([1.0, 1.0, 4.0, 1.0])}
    normal = np.stack([course + sign * sd[skill] for skill in "ab" for sign in (1, -1)])
    twins = np.repeat(course[None], 4, axis=0)
    locks = twins.copy()
    locks[0, 5:, 2] += 0.5 * np.arange(1, steps - 4)  # 0.5, 1.0, ...: exactly 3 sd at tick 10, above it at 11
    locks[1, 3:, 0] += 10.0  # visible at its onset
    locks[2, 2:, 1] += 1.0  # never above 1 sd
    locks[3, 5:, 2] += 5.0  # 5 sd in skill "a", 1.25 in skill "b": never visible
    labels = np.array(["a", "a", "a", "b"])
    names = tuple(f"c{i}" for i in range(channels))
    return (Sequences(locks, labels, names, seeds=np.arange(4), rate_hz=40.0),
            Sequences(twins, labels, names, seeds=np.arange(4), rate_hz=40.0),
            Sequences(normal, np.repeat(["a", "b"], 2), names, rate_hz=40.0))


def test_visible_onset_is_the_first_tick_above_three_normal_sd_of_the_skill():
    locks, twins, normal = ramps()
    onsets = Onsets.against(locks, np.array([3, 1, 2, 3]), twins, normal)
    assert onsets.onset_s.tolist() == [5 / 40, 3 / 40, 2 / 40, 5 / 40]
    assert onsets.visible_s[:2].tolist() == [11 / 40, 3 / 40] and np.isnan(onsets.visible_s[2:]).all()


def test_latency_from_the_visible_onset():
    """Counted from the visible tick, a flag between the onset and it is early (negative); faults
    never visible are left out of the percentiles, and a 2 Hz flag's time is its step / 2 s."""
    locks, twins, normal = ramps()
    onsets = Onsets.against(locks, np.array([3, 1, 2, 3]), twins, normal)
    at_40 = Flagged(np.array([True, True, True, False]), np.array([13, 3, 4, -1]),
                    np.array([8, 0, 2, np.nan]) / 40, np.zeros((4, 20, 4)))
    assert from_visible(at_40, onsets, 40.0) == {"median_ms": 25.0, "p95_ms": 47.5, "flagged_before_visible": 0,
                                                 "never_visible": 2}
    early = Flagged(np.array([True, True, False, False]), np.array([7, 5, -1, -1]),
                    np.array([2, 2, np.nan, np.nan]) / 40, np.zeros((4, 20, 4)))
    assert from_visible(early, onsets, 40.0)["flagged_before_visible"] == 1  # tick 7, visible at 11: -100 ms
    assert from_visible(early, onsets, 40.0)["median_ms"] == -25.0  # -100 and +50 ms
    at_2 = Flagged(np.array([True, False, False, False]), np.array([1, -1, -1, -1]),
                   np.array([0.375, np.nan, np.nan, np.nan]), np.zeros((4, 1, 4)))
    entry = latency_ms(at_2, onsets, 2.0, 1)
    assert entry["quiet_100ms"] == 1
    assert entry["median_ms"] == 375.0 and entry["from_visible"]["median_ms"] == 225.0  # 0.5 s - 11 / 40 s


def evaluated(lock_p95_from_visible: float, locks_before_visible: int) -> dict:
    """What `served.evaluate` gives, the numbers `rate.spread` summarises."""
    def kind(p95: float, before: int) -> dict:
        return {"median_ms": 0.0, "p95_ms": 500.0, "from_visible": {"median_ms": -25.0, "p95_ms": p95,
                                                                     "flagged_before_visible": before,
                                                                     "never_visible": 3},
                "quiet_100ms": before // 10}

    return {"normal_episodes_flagged": 0.03, "normal_episodes_flagged_resplits": 0.007,
            "detection": {"lock": 0.997, "falling_object": 1.0}, "isolation_at_detection": 0.95,
            "latency": {"lock": kind(lock_p95_from_visible, locks_before_visible), "falling_object": kind(0.0, 0)}}


def test_latency_from_the_visible_onset_across_trainings_and_in_the_table():
    runs = [evaluated(150.0, 600), evaluated(170.0, 650)]
    across = spread(runs)
    assert across["lock_latency_from_visible_p95_ms"] == {"mean": 160.0, "min": 150.0, "max": 170.0}
    assert across["lock_latency_p95_ms"] == {"mean": 500.0, "min": 500.0, "max": 500.0}
    table = markdown({"rate_hz": 40.0, "trainings": 2, "latency": runs[0]["latency"],
                      "rates": {"40": {"across_trainings": {"online": across}}}})
    assert "| 40 Hz | online | -25 / 160 (150-170) | 625 (600-650) | -25 / 0 | 0 |" in table
    assert "3 locks and 3 falling objects never depart so far" in table
    assert across["lock_quiet_100ms"] == {"mean": 62.5, "min": 60, "max": 65}
    assert "| 40 Hz | online | 62 (60-65) | 0 |" in table


def test_quiet_faults_stay_within_the_served_spread_for_100_ms(calibrated):
    """A fault counts as quiet when no channel departs from its twin by more than the calibration's
    one-step spread at any observation from its onset to 100 ms after it."""
    model, test = calibrated
    steps, width = test.data.shape[1:]
    spread = model.calibration("online", 1).error_std[:steps] * model.normaliser.std  # channel units
    departure = np.zeros((4, steps, width))
    departure[0, 4, 1] = 3.0 * spread[4, 1]  # loud at its onset
    departure[1, 4:] = 0.5 * spread[4:]  # within the spread throughout
    departure[2, 9, 2] = 3.0 * spread[9, 2]  # loud, but only long after its onset
    departure[3, 3, 0] = 3.0 * spread[3, 0]  # loud before its onset: not counted
    onsets = Onsets(Sequences(test.data[:4], test.labels[:4], test.channel_names, rate_hz=model.rate_hz),
                    np.arange(4), np.full(4, 4 / model.rate_hz), np.full(4, np.nan), departure)
    window = 1.5 / model.rate_hz  # steps 4 and 5
    assert quiet(model, "online", onsets, window) == 3
    departure[1, 5, 0] = 1.1 * spread[5, 0]
    assert quiet(model, "online", onsets, window) == 2


def test_flags_are_the_services_and_count_from_the_onset(calibrated):
    model, test = calibrated
    data = test.data[:4].copy()
    data[:, 9:, 1] += 25.0  # a large fault from step 9 on
    onset_s = np.array([9, 9, 12, 20]) / model.rate_hz  # the third "began" later; the fourth after the end
    result = flagged(model, "online", data, onset_s, 0.01)
    served, _ = flag_steps(model.score(data, "online", 1).energy, model.calibration("online", 1), 0.01, "episode")
    assert served[:, 9].all()
    assert result.detected.tolist() == [True, True, True, False]
    assert result.first.tolist()[:3] == [9, 9, 12] and result.first[3] == -1
    assert np.allclose(result.latency_s[:3], 0.0) and np.isnan(result.latency_s[3])


def test_subsampling_and_percentiles(skills):
    _, test = skills
    fast = Sequences(test.data, test.labels, test.channel_names, rate_hz=40.0)
    slow = subsampled(fast, 8.0)
    assert slow.rate_hz == 8.0 and np.array_equal(slow.data, test.data[:, ::5])
    with pytest.raises(ValueError, match="whole number"):
        subsampled(fast, 3.0)
    assert percentiles_ms(np.array([0.025, 0.05, 0.075])) == {"median_ms": 50.0, "p95_ms": 72.5}
    assert percentiles_ms(np.array([])) == {"median_ms": None, "p95_ms": None}


def test_flagged_over_resplits_is_the_conformal_rate(rng):
    """Over re-splits of any pool of distinct peaks, a test episode is above the calibration set's
    conformal threshold with probability (n + 1 - k) / (n + 1): 1/151 for 150 episodes at 1 %."""
    peaks = rng.lognormal(size=300)
    share = flagged_over_resplits(peaks[:150], peaks[150:], 0.01)
    assert share == pytest.approx(1 / 151, abs=1e-3)
    assert flagged_over_resplits(peaks[:150], peaks[150:], 0.05) == pytest.approx(7 / 151, abs=3e-3)  # rank 144


def test_each_latency_and_the_latency_figure(tmp_path):
    """Every episode keeps its latency (None: never flagged), and the figure draws them per rate,
    also where a rate flagged nothing of a kind."""
    assert each_ms(np.array([0.025, np.nan, 0.0])) == [25.0, None, 0.0]
    modes = {"online": {"latency_ms_each": {"lock": [25.0, None, 50.0], "falling_object": [0.0, 75.0]}}}
    missed = {"online": {"latency_ms_each": {"lock": [None, None, None], "falling_object": [500.0, None]}}}
    result = {"mode": "online", "fpr": 0.01, "rates": {"40": {"modes": modes}, "2": {"modes": missed}}}
    path = write_latency_figure(result, tmp_path / "latency.png")
    assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
