"""Does the featured network recall the route round the post from the cue, or follow the arm?

A probe beyond the benchmark (docs/varied_levers.md): on `pick_place_around`, the steps where the
end effector moves across the cube-goal route by more than `MOVE` normalised units, and whether
the network's online expectation of that step moves the same way. An expectation that recalls
the route from the cue expects the normal episodes' detours and not the `wrong_side` faults';
one that extrapolates the motion already begun expects both alike.

It also asks whether the route can be recalled from the cue at all by what learns from ~40
demonstrations: given each demonstration's route (the side of its post offset), how often a
logistic regression names it from the cue (5-fold cross-validation), and how often 2-means on
the whole demonstrations, without the routes, splits them by route.

    python -m lab.route_probe DATA_DIR [--context hidden] [--no-noise]
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import typer
from sklearn.cluster import KMeans
from sklearn.linear_model import LogisticRegression
from sklearn.model_selection import StratifiedKFold, cross_val_score
from sklearn.pipeline import make_pipeline
from sklearn.preprocessing import StandardScaler

from neural_asm.experiments.varied.data import ensure_varied_sets, load_varied_benchmark
from neural_asm.experiments.varied.methods import train_neural_asm
from neural_asm.models.asm import NeuralASM
from neural_asm.models.config import PRECISE
from neural_asm.sim.varied import context_columns

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


def route_naming(x: np.ndarray, route: np.ndarray, context: list[int], seed: int = 0) -> dict[str, float]:
    """Normalised demonstrations x (N, T, D) of one skill and their routes (N,) bool: the share of
    routes named from the cue's `context` channels and from the whole cue, and the share of
    demonstrations 2-means puts with their route (either labelling of its two clusters)."""
    folds = StratifiedKFold(5, shuffle=True, random_state=seed)

    def named(cols: list[int]) -> float:
        logistic = make_pipeline(StandardScaler(), LogisticRegression(max_iter=5000))
        return float(cross_val_score(logistic, x[:, 0, cols], route, cv=folds).mean())

    clusters = KMeans(2, n_init=20, random_state=seed).fit_predict(x.reshape(len(x), -1)) == 1
    return {"context": named(context), "cue": named(list(range(x.shape[2]))),
            "two_means": float(max((clusters == route).mean(), (clusters != route).mean()))}


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
    sets, _ = ensure_varied_sets(data)
    demos = [e for e in sets["demos"] if e.skill == "pick_place_around"]
    route = np.array([e.task["post_offset"] > 0 for e in demos])
    x = model.normaliser.normalise(np.stack([e.observations for e in demos])[..., context_columns(demos[0].channel_names, context)])
    r = route_naming(x, route, list(bench.context_channels))
    print(f"{len(demos)} pick_place_around demonstrations, routes told: named from the {len(bench.context_channels)} "
          f"context channels {100 * r['context']:.0f} %, from the whole cue {100 * r['cue']:.0f} % (5-fold); "
          f"routes not told: 2-means puts {100 * r['two_means']:.0f} % with their route")


if __name__ == "__main__":
    typer.run(main)
