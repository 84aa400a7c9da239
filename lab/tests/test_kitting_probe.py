"""The kitting probe's recognition variants: held after k steps, or told."""

from types import SimpleNamespace

import numpy as np

from lab.kitting_probe import picks
from neural_asm.models.calibration import Calibration


def test_recognition_is_held_after_k_steps_or_told():
    steps, width = 6, 2
    means = np.stack([np.zeros((steps, width)), np.ones((steps, width))])  # skill a errs 0, skill b 1
    cal = Calibration("offline", 1, np.ones((steps, width)), "test", error_mean=means, skills=("a", "b"))
    errors = np.concatenate([np.ones((1, 2, width)), np.zeros((1, steps - 2, width))], axis=1)  # b, then a
    every = picks(cal, errors, None, "every step", 0)[0]
    assert every[0] == -1 and every[1] == 1 and every[-1] == 0  # re-recognised as the steps come
    held = picks(cal, errors, None, "held", 2)[0]
    assert held.tolist() == [-1, 1, 1, 1, 1, 1]  # from the first two steps, then held
    told = picks(cal, errors, SimpleNamespace(skills=np.array(["a"])), "told", 0)[0]
    assert (told == 0).all()
