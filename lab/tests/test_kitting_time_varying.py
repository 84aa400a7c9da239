"""The time-varying threshold's scales over the steps segments reach, and the silent-pad test."""

from types import SimpleNamespace

import numpy as np

from lab.kitting_silent_pad import silent
from lab.kitting_time_varying import normalised_peaks, scales


def test_scales_come_from_the_segments_still_running_and_are_floored():
    energies = np.array([[100.0, 1.0, 1.0, 50.0], [100.0, 2.0, 3.0, 0.0], [100.0, 1.0, 2.0, 0.0]])
    lengths = np.array([4, 3, 3])  # the last step belongs to the first segment only
    s = scales(energies, lengths)
    assert s[0] == 100.0 and s[3] == 50.0  # not dragged down by the padding's zeros
    np.testing.assert_allclose(s[1:3], [1.9, 2.9])  # 95 % quantiles of (1, 2, 1) and (1, 3, 2)
    floored = scales(np.array([[1e-6, 10.0, 10.0], [1e-6, 10.0, 10.0]]), np.array([3, 3]))
    assert floored[0] == 0.05 * 10.0
    peaks = normalised_peaks(energies, lengths, s)
    np.testing.assert_allclose(peaks, [1.0, 2 / 1.9, 1.0])  # each step against its own scale, padding ignored


def test_a_pad_is_silent_only_if_it_reads_zero_over_the_whole_segment():
    data = np.ones((3, 4, 6))
    data[0, :, 5] = 0.0  # the right pad silent
    data[1, :2, 4] = 0.0  # the left pad silent for half of it
    data[2, :3, 4] = 0.0  # silent over its own three steps, not the padding
    segs = SimpleNamespace(data=data, lengths=np.array([4, 4, 3]))
    assert silent(segs).tolist() == [True, False, True]
