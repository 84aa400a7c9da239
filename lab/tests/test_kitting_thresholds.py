"""The threshold probe's census of the normal peaks above a threshold."""

from types import SimpleNamespace

import numpy as np

from lab.kitting_thresholds import above


def test_above_names_day_skill_and_a_silent_left_pad():
    data = np.ones((3, 4, 6))
    data[1, :, 4] = 0.0  # the left pad reads 0 throughout
    data[2, :2, 4] = 0.0  # silent for two of its three steps only
    segs = SimpleNamespace(runs=np.array(["2018y05m24d1", "2018y05m24d2", "2018y06m10d1"]),
                           skills=np.array(["3", "3", "5"]), data=data, lengths=np.array([4, 4, 3]))
    counts = above(segs, np.array([5.0, 9.0, 7.0]), threshold=6.0)
    assert counts == {("2018y05m24", "3", True): 1, ("2018y06m10", "5", False): 1}
