"""Does the featured network recall the route round the post from the cue, or follow the arm?

A probe beyond the benchmark (docs/varied_levers.md): on `pick_place_around`, the steps where the
end effector moves across the cube-goal route by more than `MOVE` normalised units, and whether
the network's online expectation of that step moves the same way. An expectation that recalls
the route from the cue expects the normal episodes' detours and not the `wrong_side` faults';
one that extrapolates the motion already begun expects both alike.

    python -m experiments.varied.route_probe DATA_DIR [--context hidden] [--no-noise]
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import typer

from experiments.varied.data import load_varied_benchmark
from experiments.varied.methods import train_neural_asm
from models.asm import NeuralASM
from models.config import PRECISE

MOVE = 0.5  # normalised units of ee_x across the route (about 3.8 cm)


def across_moves(model: NeuralASM, sequences: np.ndarray, channel: int) -> dict[str, float]:
    """How often the expected across-route move has the actual one's sign: over every step that
    moves more than `MOVE`, at each episode's first such step, and the median ratio of expected
    to actual move there."""
    x = model.normaliser.normalise(sequences)
    expected = x - model.errors(sequences, "online")
    actual_move = x[:, 1:, channel] - x[:, :-1, channel]
    expected_move = expected[:, 1:, channel] - x[:, :-1, channel]
    big = np.abs(actual_move) > MOVE
    right = np.sign(actual_move) == np.sign(expected_move)
    rows = np.flatnonzero(big.any(axis=1))
    first = big[rows].argmax(axis=1)
    return {"episodes": len(sequences), "steps": int(big.sum()), "right": float(right[big].mean()),
            "right_first": float(right[rows, first].mean()),
            "ratio_first": float(np.median(np.abs(expected_move[rows, first]) / np.abs(actual_move[rows, first])))}


def main(data: Path, context: str = "observed", noise: bool = typer.Option(True, help="the preset's training noise")
         ) -> None:
    bench = load_varied_benchmark(data, context)
    config = PRECISE if noise else PRECISE.with_(training_noise=0.0)
    model = train_neural_asm(bench, config, progress=False)
    channel = bench.channel_names.index("ee_x")
    normal = bench.test.data[bench.test.labels == "pick_place_around"]
    wrong = bench.faults.data[bench.kinds == "wrong_side"]
    for name, sequences in (("normal pick_place_around", normal), ("wrong_side faults", wrong)):
        r = across_moves(model, sequences, channel)
        print(f"{name}: {r['episodes']} episodes, {r['steps']} steps moving > {MOVE} across; expected direction "
              f"right {100 * r['right']:.0f} %, at the first such step {100 * r['right_first']:.0f} %, "
              f"expected / actual move there {r['ratio_first']:.2f}")


if __name__ == "__main__":
    typer.run(main)
