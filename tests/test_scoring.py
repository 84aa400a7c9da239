"""Precision weighting of prediction errors: spreads and whitening by a precision matrix."""

import numpy as np
import pytest

from models import checkpoint
from models.calibration import error_precision, error_spread
from models.config import SCORING
from models.fault import isolate, isolate_rows
from models.scoring import energy


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
    diagonal = model.calibrate(train.data, test.data, "offline", 1, covariance="diagonal")
    assert diagonal.error_precision is None
    errors = model.errors(test.data, "offline", 1)
    np.testing.assert_allclose(model.score(test.data, "offline").energy, energy(errors, diagonal.error_std))
    with pytest.raises(ValueError, match="covariance"):
        model.calibrate(train.data, test.data, "offline", 1, covariance="sparse")  # type: ignore[arg-type]


def test_spreads_are_floored_at_the_floor_of_the_model_rate(trained, skills):
    train, test = skills
    model = checkpoint.from_bytes(checkpoint.to_bytes(trained))
    at_2hz = model.calibrate(train.data, test.data, "online", 1).error_std
    model.rate_hz = 40.0  # the same errors, as if observed every 25 ms
    at_40hz = model.calibrate(train.data, test.data, "online", 1).error_std
    floor_2hz, floor_40hz = SCORING.spread_floor(2.0), SCORING.spread_floor(40.0)
    assert at_2hz.min() == pytest.approx(floor_2hz) and at_40hz.min() >= floor_40hz
    below = at_40hz < floor_2hz  # spreads the 2 Hz floor hid
    assert below.any()
    np.testing.assert_allclose(at_40hz[~below], at_2hz[~below])


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
