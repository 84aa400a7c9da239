"""Precision weighting of prediction errors: spreads and whitening by a precision matrix."""

import numpy as np
import pytest

from neural_asm.models import checkpoint
from neural_asm.models.asm import weigh_step
from neural_asm.models.calibration import Weighting, error_precision, error_spread
from neural_asm.models.config import SCORING
from neural_asm.models.fault import isolate, isolate_rows
from neural_asm.models.scoring import energy
from neural_asm.pipelines.default_model import calibrated_as_now


@pytest.fixture
def correlated(rng):
    """Normal errors (N, T, D) in which channel 1 follows channel 0 closely and channel 2 is alone."""
    a = rng.standard_normal((400, 3))
    errors = np.stack([a[:, 0], a[:, 0] + 0.1 * a[:, 1], a[:, 2]], axis=-1)
    return errors[:, None, :].repeat(2, axis=1)  # two identical steps


def test_whitening_scores_a_broken_correlation_above_a_usual_one(correlated):
    spread = error_spread(correlated)
    precision = error_precision(correlated, spread)
    usual = np.array([[[2.0, 2.0, 0.0]]])  # both channels off together, as they normally are
    broken = np.array([[[2.0, -2.0, 0.0]]])  # the same sizes, against their correlation
    diagonal = energy(usual, spread), energy(broken, spread)
    whitened = energy(usual, spread, precision), energy(broken, spread, precision)
    assert diagonal[0] == pytest.approx(diagonal[1])
    assert whitened[1] > 20 * whitened[0]


def test_identity_precision_is_the_diagonal_energy(rng):
    errors = rng.standard_normal((5, 4, 6))
    spread = np.abs(rng.standard_normal((4, 6))) + 0.5
    eye = np.broadcast_to(np.eye(6), (4, 6, 6))
    np.testing.assert_allclose(energy(errors, spread, eye), energy(errors, spread))


def test_calibration_whitens_by_default_and_diagonal_on_request(trained, skills):
    model = checkpoint.from_bytes(checkpoint.to_bytes(trained))  # a copy: `trained` is shared
    train, test = skills
    full = model.calibrate(train.data, test.data, "offline", 1)
    steps, channels = full.error_std.shape
    assert full.error_precision is not None and full.error_precision.shape == (steps, channels, channels)
    diagonal = model.calibrate(train.data, test.data, "offline", 1, weighting=Weighting("diagonal"))
    assert diagonal.error_precision is None
    errors = model.errors(test.data, "offline", 1)
    np.testing.assert_allclose(model.score(test.data, "offline").energy, energy(errors, diagonal.error_std))
    with pytest.raises(ValueError, match="covariance"):
        model.calibrate(train.data, test.data, "offline", 1, weighting=Weighting("sparse"))  # type: ignore[arg-type]


def rms(errors: np.ndarray) -> np.ndarray:
    return np.sqrt((errors.astype(np.float64) ** 2).mean(axis=0))


def test_spreads_are_floored_at_the_floor_of_the_model_rate(trained, skills):
    """At 2 Hz the spreads are the errors' RMS; at 40 Hz that of the errors less each step's
    mean; each floored at its rate's floor."""
    train, test = skills
    model = checkpoint.from_bytes(checkpoint.to_bytes(trained))
    errors = model.errors(train.data, "online", 1).astype(np.float64)
    at_2hz = model.calibrate(train.data, test.data, "online", 1).error_std
    model.rate_hz = 40.0  # the same errors, as if observed every 25 ms
    at_40hz = model.calibrate(train.data, test.data, "online", 1).error_std
    floor_2hz, floor_40hz = SCORING.spread_floor(2.0), SCORING.spread_floor(40.0)
    assert at_2hz.min() == pytest.approx(floor_2hz) and (at_40hz < floor_2hz).any()  # spreads the 2 Hz floor hid
    np.testing.assert_allclose(at_2hz, np.maximum(rms(errors), floor_2hz))
    np.testing.assert_allclose(at_40hz, np.maximum(rms(errors - errors.mean(axis=0)), floor_40hz))


def test_at_40_hz_each_skills_mean_error_is_taken_out_before_weighing(trained, skills):
    """The error every normal episode of a skill makes alike at a step weighs nothing at 40 Hz,
    once the episode's steps before it have shown which skill it is; at 2 Hz errors are weighed
    as they are. Whole episodes and streamed steps agree, alone or batched with a stream weighed
    otherwise."""
    train, test = skills
    model = checkpoint.from_bytes(checkpoint.to_bytes(trained))
    assert model.calibrate(train.data, test.data, "online", 1, labels=train.labels).error_mean is None
    model.rate_hz = 40.0
    cal = model.calibrate(train.data, test.data, "online", 1, labels=train.labels)
    errors = model.errors(train.data, "online", 1)
    assert cal.skills == tuple(sorted(set(map(str, train.labels)))) and len(cal.skills) == 3
    for k, skill in enumerate(cal.skills):
        np.testing.assert_allclose(cal.error_mean[k], errors[train.labels.astype(str) == skill].mean(axis=0), rtol=1e-5)
    as_each_skill = cal.energy(cal.error_mean)  # an episode erring exactly as each skill does on average
    assert np.abs(as_each_skill[:, 1:]).max() < 1e-9 and (as_each_skill[:, 0] > 0).any()  # recognised from step 1
    test_errors = model.errors(test.data, "online", 1)
    stream = model.stream("online", 1)
    streamed = [stream.step(x) for x in test.data[0]]
    np.testing.assert_allclose([s.energy for s in streamed], model.score(test.data[:1], "online").energy[0], rtol=1e-4)
    np.testing.assert_allclose([s.weighted_errors for s in streamed], cal.weigh(test_errors[:1])[0], rtol=1e-4, atol=1e-4)
    pooled = model.calibrate(train.data, test.data, "offline", 1)  # no labels: one mean for all
    assert pooled.skills == ("all",)
    offline = model.errors(train.data, "offline", 1)
    np.testing.assert_allclose(pooled.weigh(errors[:1]), (errors[:1] - offline.mean(axis=0)) / pooled.error_std,
                               rtol=1e-5, atol=1e-6)
    calibrations, misfit = [cal, None, pooled], [np.zeros(3), np.zeros(0), np.zeros(1)]
    for t in range(4):  # the misfits carried from step to step pick the skill as whole episodes do
        weighted, energies, misfit = weigh_step(np.stack([errors[0, t]] * 3), calibrations, [t] * 3, misfit)
        np.testing.assert_allclose(weighted[0], cal.weigh(errors[:1])[0, t], rtol=1e-6)
        np.testing.assert_allclose(energies, [cal.energy(errors[:1])[0, t], energy(errors[:1])[0, t],
                                              pooled.energy(errors[:1])[0, t]], rtol=1e-6)


def test_a_stream_names_the_skill_it_recognises_and_an_oracle_may_be_told_it(trained, skills):
    """A served step's skill is the one whose mean errors it takes out, as whole episodes are
    centred; told each episode's skill, the calibration takes out that skill's means from step 0."""
    train, test = skills
    model = checkpoint.from_bytes(checkpoint.to_bytes(trained))
    model.rate_hz = 40.0
    cal = model.calibrate(train.data, test.data, "online", 1, labels=train.labels)
    recognised = cal.recognised(model.errors(test.data, "online", 1))
    for i in range(len(test.data)):
        stream = model.stream("online", 1)
        named = [stream.step(x).skill for x in test.data[i]]
        assert named == [None if k < 0 else cal.skills[k] for k in recognised[i]]
    assert named[0] is None and set(named[1:]) <= set(cal.skills)
    assert np.abs(cal.energy(cal.error_mean, told=list(cal.skills))).max() < 1e-9
    rotated = list(cal.skills[1:] + cal.skills[:1])
    assert (cal.energy(cal.error_mean, told=rotated).max(axis=1) > 1e-3).all()


def test_a_40_hz_model_calibrated_by_the_older_rule_is_told_apart(trained, skills):
    """The default model's cache recalibrates a 40 Hz checkpoint whose calibrations keep no mean errors."""
    train, test = skills
    model = checkpoint.from_bytes(checkpoint.to_bytes(trained))
    assert calibrated_as_now(model)
    model.rate_hz = 40.0  # calibrated at 2 Hz, as a 40 Hz checkpoint of the older rule was
    assert not calibrated_as_now(model)
    model.calibrate(train.data, test.data, "online", 1)
    assert not calibrated_as_now(model)  # offline still of the older rule
    model.calibrate(train.data, test.data, "offline", 1)
    assert calibrated_as_now(model)


def test_a_batch_is_isolated_and_ranked_as_each_row_alone(rng):
    names = ("joint1", "joint2", "joint3", "force_x", "force_y")
    errors = rng.standard_normal((6, 5))
    errors[0] = [0.5, -0.5, 0.1, 3.0, 0.5]  # ties keep channel order; the force leads, joint1 is isolated
    isolated, ranked, sizes = isolate_rows(errors, names)
    for row, joint, channels, size in zip(errors, isolated, ranked, sizes):
        by_size = sorted(range(5), key=lambda i: -abs(row[i]))  # sorted() is stable
        assert channels == [names[i] for i in by_size]
        assert size == [abs(row[i]) for i in by_size]
        assert joint == names[max(range(3), key=lambda i: abs(row[i]))]
    assert ranked[0] == ["force_x", "joint1", "joint2", "force_y", "joint3"]
    assert isolated[0] == "joint1"
    assert isolate(errors[3], names) == (isolated[3], ranked[3], sizes[3])
