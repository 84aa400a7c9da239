"""Fit time and held-out error of every baseline detector at the varied benchmark's size.

4 skills x 40 demonstrations, 15 steps, 30 channels of which 4 are context, on a synthetic
task (trajectories linear and non-linear in the context, a random speed per episode, noise);
200 held-out episodes measure the one-step mean squared error (steps 1..T-1, normalised).
Times are printed in seconds and as a ratio to a reference measured in the same run (100
ridge fits of ``models.one_step.RidgeOneStep`` on the same demonstrations), because these
machines are shared and noisy. One JSON object is the last line.

    python benchmarks/bench_detectors.py [--seed 0] [--quick]

``--quick``: 5 demonstrations per skill, 20 held-out episodes and the recurrent rivals trained
for 2 epochs, in seconds; the test suite runs it so the script keeps working (its numbers mean
nothing).
"""

from __future__ import annotations

import neural_asm.runtime  # noqa: F401  (first: one BLAS thread, no display)

import argparse
import json
import time
from dataclasses import replace

import numpy as np

from neural_asm.models.one_step import RidgeOneStep
from neural_asm.rivals.registry import line_up
from neural_asm.rivals.sequence import RecurrentDetector

SKILLS, CONTEXT, STEPS, CHANNELS = ("pick", "place", "push", "stack"), 4, 15, 30


def varied(n_per_skill: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    structure = np.random.default_rng(1000)
    gain = 0.6 * structure.standard_normal((len(SKILLS), CONTEXT, STEPS, CHANNELS))
    bend = structure.standard_normal((len(SKILLS), STEPS, CHANNELS))
    t = np.linspace(0.0, 1.0, STEPS)
    xs = []
    for k in range(len(SKILLS)):
        c = rng.uniform(-1.0, 1.0, (n_per_skill, CONTEXT))
        speed = rng.uniform(0.8, 1.2, n_per_skill)
        x = np.sin(2 * np.pi * (speed[:, None] * t)[..., None] + np.arange(CHANNELS) / 5)
        x = x + np.einsum("nc,ctd->ntd", c, gain[k]) + np.tanh(2 * c[:, :1, None]) * bend[k]
        x += 0.1 * rng.standard_normal(x.shape)
        x[:, :, :CONTEXT] = c[:, None] + 0.02 * rng.standard_normal((n_per_skill, STEPS, CONTEXT))
        xs.append(x)
    return np.concatenate(xs), np.repeat(np.array(SKILLS), n_per_skill)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--quick", action="store_true",
                        help="tiny sizes (seconds, not minutes): checks the script runs, measures nothing")
    args = parser.parse_args()
    demos, skills = varied(5 if args.quick else 40, args.seed)
    test, test_skills = varied(5 if args.quick else 50, args.seed + 1)
    mean, std = demos.mean((0, 1)), demos.std((0, 1))
    demos, test = (demos - mean) / std, (test - mean) / std

    start = time.perf_counter()
    for _ in range(100):
        RidgeOneStep.fit(demos)
    reference = time.perf_counter() - start
    results = {}
    for det in line_up("varied"):
        if args.quick and isinstance(det, RecurrentDetector):
            det.config = replace(det.config, max_epochs=2)
        start = time.perf_counter()
        det.fit(demos, skills, list(range(CONTEXT)), seed=args.seed)
        fit = time.perf_counter() - start
        error = float(((test - det.expected(test, test_skills))[:, 1:] ** 2).mean())
        results[det.name] = {
            "fit_s": round(fit, 3),
            "fit_vs_reference": round(fit / reference, 2),
            "test_mse": round(error, 4),
        }
        print(f"{det.label:55s} fit {fit:6.2f} s ({fit / reference:7.2f} x ref)  held-out MSE {error:.4f}")
    print(json.dumps({"reference_s": round(reference, 3), "detectors": results}))


if __name__ == "__main__":
    main()
