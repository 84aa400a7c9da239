"""The skill-memory probe's cache, its template courses and its table cells."""

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
    assert cell(runs, "auroc") == "0.93 (0.90-0.95)"
    assert cell(runs, "detected") == "50 %"
