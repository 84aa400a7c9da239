"""The route probe: whether an expectation moves the way the arm moves across the route."""

from types import SimpleNamespace

import numpy as np

from lab.route_probe import across_moves


def _model(expected_of):
    """A stand-in with the two things the probe reads: an identity normaliser and online errors."""
    identity = SimpleNamespace(normalise=lambda x: np.asarray(x, np.float32))
    return SimpleNamespace(normaliser=identity, errors=lambda x, mode: x - expected_of(x))


def _detours(rng):
    """Episodes that sit still, then move across by 2 units a step for three steps, either way."""
    x = np.zeros((6, 10, 2), np.float32)
    sides = np.array([1, -1, 1, -1, 1, 1], np.float32)
    x[:, 4:7, 0] = sides[:, None] * np.array([2.0, 4.0, 6.0])
    x[:, 7:, 0] = sides[:, None] * 6.0
    x[..., 1] = rng.normal(size=(6, 10))
    return x


def test_an_expectation_that_knows_the_route_is_right_and_one_that_follows_is_late(rng):
    x = _detours(rng)
    recalled = across_moves(_model(lambda s: s), x, 0)  # expects every step exactly
    assert recalled["steps"] == 18 and recalled["right"] == 1.0 and recalled["ratio_first"] == 1.0

    def follows(s):  # expects the last step's move again
        e = s.copy()
        e[:, 2:, 0] = 2 * s[:, 1:-1, 0] - s[:, :-2, 0]
        return e

    late = across_moves(_model(follows), x, 0)
    assert late["right_first"] == 0.0  # the first move is never foreseen
    assert 0.5 < late["right"] < 1.0 and late["ratio_first"] == 0.0

    wrong = across_moves(_model(lambda s: np.concatenate([s[:, :1], 2 * s[:, :-1] - s[:, 1:]], axis=1)), x, 0)
    assert wrong["right"] == 0.0


def test_routes_set_by_a_context_channel_are_named_from_it_and_found_without_labels(rng):
    from lab.route_probe import route_naming

    route = np.arange(40) % 2 == 0
    x = rng.normal(size=(40, 8, 4))
    x[:, 0, 3] = np.where(route, 1.0, -1.0) + 0.1 * rng.normal(size=40)  # the context channel decides the route
    x[:, 3:, 0] += np.where(route, 4.0, -4.0)[:, None]  # and the detour goes that way
    told = route_naming(x, route, [3])
    assert told["context"] == 1.0 and told["two_means"] == 1.0
    x[:, 0, 3] = rng.normal(size=40)  # a cue that says nothing of the route
    assert route_naming(x, route, [3])["context"] < 0.8
