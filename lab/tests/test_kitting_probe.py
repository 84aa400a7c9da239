"""The kitting probe's recognition variants: held after k steps, or told."""

from types import SimpleNamespace

import numpy as np

from lab.kitting_probe import picks, recognised_from
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


def test_recognition_from_some_channels_ignores_the_others():
    steps = 5
    means = np.stack([np.zeros((steps, 2)), np.ones((steps, 2))])  # skill a errs 0 on both channels, b 1
    cal = Calibration("offline", 1, np.ones((steps, 2)), "test", error_mean=means, skills=("a", "b"))
    errors = np.zeros((1, steps, 2))
    errors[..., 1] = 5.0  # channel 1 says b loudly; channel 0 says a
    assert (cal.recognised(errors)[0, 1:] == 1).all()
    assert (recognised_from(cal, errors, [0])[0, 1:] == 0).all()


def test_scored_only_channels_do_not_move_the_hidden_state_but_are_learned():
    from lab.kitting_probe import ScoredOnly
    from neural_asm.models.config import FAST
    from neural_asm.models.train import train

    net = type("Net", (ScoredOnly,), {"scored": (1,)})(2, FAST.with_(hidden_size=8, epochs=3))
    prior = np.zeros((1, 8), np.float32)
    x = np.array([[0.5, 0.0]], np.float32)
    moved = net.infer(prior, x)
    assert np.allclose(net.infer(prior, x + np.array([[0.0, 3.0]], np.float32)), moved)  # channel 1 ignored
    assert not np.allclose(net.infer(prior, x + np.array([[3.0, 0.0]], np.float32)), moved)  # channel 0 drives z
    before = net.w_f[1].copy()
    train(net, np.random.default_rng(0).standard_normal((4, 6, 2)).astype(np.float32), progress=False)
    assert not np.allclose(net.w_f[1], before)  # its expectation is still learned


def test_motion_by_day_counts_each_day_s_segments_and_when_they_move():
    from lab.kitting_probe import motion_by_day

    data = np.zeros((3, 10, 6))
    data[0, 4:, 2] = data[1, 6:, 2] = data[2, 2:, 2] = 0.1  # the arm moves from step 4, 6, 2
    segs = SimpleNamespace(runs=np.array(["2018y05m26d10H00M00S", "2018y05m26d11H00M00S", "2018y06m13d09H00M00S"]),
                           data=data, skills=np.array(["5", "5", "5"]),
                           anomalies=np.array([None, "no_object", None], dtype=object),
                           normal=np.array([True, False, True]))
    assert motion_by_day(segs) == {"2018y05m26": {"normal 5": (1, 4.0), "no_object": (1, 6.0)},
                                   "2018y06m13": {"normal 5": (1, 2.0)}}
