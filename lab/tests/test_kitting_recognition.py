"""The recognition probe's running mean and its read-out, named at each sequence's own step."""

import numpy as np

from lab.kitting_recognition import fit_readout, named_at, running_mean


def test_running_mean_is_the_mean_of_the_steps_so_far():
    values = np.array([[[1.0], [3.0], [8.0]]])
    assert running_mean(values)[0, :, 0].tolist() == [1.0, 2.0, 4.0]


def test_the_read_out_learns_the_skill_from_own_steps_only(rng):
    n, steps = 40, 6
    skills = np.array(["a", "b"] * (n // 2))
    features = rng.normal(size=(n, steps, 3)) * 0.1
    features[skills == "b", :, 0] += 2.0
    lengths = np.full(n, 4)
    features[:, 4:] = np.where(skills[:, None, None] == "a", 2.0, 0.0)  # padding says the opposite
    readout = fit_readout(features, lengths, skills)
    assert (named_at(readout, features, lengths - 1) == skills).all()
