"""The skill-memory probe's cache, its template courses and its table cells."""

import math

import numpy as np

from lab.kitting_skills import cached, cell
from neural_asm.models.asm import NeuralASM
from neural_asm.models.config import FAST


def test_a_network_is_trained_once_then_read_from_the_cache(tmp_path, rng):
    calls = []

    def fit():
        calls.append(1)
        return NeuralASM.fit(rng.standard_normal((3, 5, 2)), ["a", "b"], FAST.with_(hidden_size=4, epochs=1),
                             progress=False)

    first = cached(tmp_path / "m.safetensors", fit)
    again = cached(tmp_path / "m.safetensors", fit)
    assert len(calls) == 1 and [p.name for p in tmp_path.iterdir()] == ["m.safetensors"]
    np.testing.assert_array_equal(first.net.W_F.numpy(), again.net.W_F.numpy())


def test_cells_show_the_mean_and_the_range_over_trainings():
    runs = [{"auroc": 0.9, "detected": 0.5}, {"auroc": 0.95, "detected": 0.5}]
    assert cell(runs, "auroc") == "0.925 (0.900-0.950)"  # three digits: rounds move AUROC by thousandths
    assert cell(runs, "detected") == "50 %"


def test_the_paired_test_counts_each_trainings_discordant_items_against_the_rivals():
    from lab.kitting_skills import paired

    rival = np.array([True, False, False, False, False, False, False, True])
    rows = {"m": [{"correct": np.array([True] * 7 + [False])}, {"correct": np.array([True] * 8)}],
            "r": [{"correct": rival}]}
    line = paired(rows, "m", "r")
    # training 1: 6 items right where the rival is wrong, 1 the other way; training 2: 6 and 0
    assert "| 12 | 1 |" in line and "6/1" in line and "6/0 p=0.031" in line
    assert f"{2 * sum(math.comb(13, k) for k in range(2)) / 2 ** 13:.2g}" in line  # exact two-sided, 12 of 13
