"""Speed and quality of the Neural ASM on paper-shaped data.

2 skills x 10 demonstrations, 15 steps, 25 channels: the simulated Panda's pick-and-place
demonstrations, as in the paper; 20 held-out normal episodes choose the epoch kept and
40 more (different seeds again) measure recall. Prints progress, then one JSON object as the
last line. Speed is reported as a ratio against a reference measured in the same run
(a straightforward per-sequence torch loop, batch 1, no autograd, default threads),
because these machines are shared and noisy.

    python benchmarks/bench_models.py [--faithful-epochs 1000] [--seeds 3]

Quality of the default model is averaged over training seeds (one seed's recall moves by a
few per cent with the epoch kept).
"""

from __future__ import annotations

import os

os.environ.setdefault("OMP_NUM_THREADS", "1")

import argparse  # noqa: E402
import json  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402
import torch  # noqa: E402

from models.asm import NeuralASM  # noqa: E402
from models.baselines import LinearOneStep, StepStatistics  # noqa: E402
from models.config import FAITHFUL, FAST  # noqa: E402
from experiments.fault_sweep.data import EpisodeArrays  # noqa: E402
from sim.dataset import demonstrations, held_out_normal, run_jobs  # noqa: E402

torch.set_num_threads(1)


def reference_epoch_ms(data: np.ndarray, epochs: int = 2) -> float:
    """A plain torch implementation: one sequence at a time, default intra-op threads."""
    torch.set_num_threads(os.cpu_count() or 1)
    try:
        cfg = FAST
        h, d = cfg.hidden_size, data.shape[-1]
        w_h = torch.empty(h, h).uniform_(-h**-0.5, h**-0.5)
        w_f = torch.empty(d, h).uniform_(-h**-0.5, h**-0.5)
        opt = torch.optim.Adam([w_h, w_f], lr=cfg.learning_rate)
        seqs = torch.from_numpy(data.astype(np.float32))
        start = time.perf_counter()
        with torch.no_grad():
            for _ in range(epochs):
                for seq in seqs:
                    zhat = torch.zeros(h)
                    for x in seq:
                        prior = w_h @ torch.tanh(zhat)
                        z = prior.clone()
                        for _ in range(cfg.inference_steps):
                            fz = torch.tanh(z)
                            eps_x = x - w_f @ fz
                            z += cfg.inference_rate * (-(z - prior) + (1 - fz**2) * (w_f.T @ eps_x))
                        fz = torch.tanh(z)
                        w_h.grad = -torch.outer(z - prior, torch.tanh(zhat))
                        w_f.grad = -torch.outer(x - w_f @ fz, fz)
                        opt.step()
                        zhat = z
        return (time.perf_counter() - start) / epochs * 1e3
    finally:
        torch.set_num_threads(1)


def mse(a: np.ndarray, b: np.ndarray) -> float:
    return float(((a - b)[:, 1:] ** 2).mean())  # step 0 is the cue


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--faithful-epochs", type=int, default=FAITHFUL.epochs)
    parser.add_argument("--seeds", type=int, default=3, choices=range(1, 11), metavar="1..10",
                        help="training seeds of the default model for quality")
    args = parser.parse_args()

    demos, _ = run_jobs(demonstrations(10), workers=2, desc="demonstrations")
    held_out, _ = run_jobs(held_out_normal(60), workers=2, desc="held-out episodes")
    train = EpisodeArrays.of(demos)
    validation = EpisodeArrays.of(held_out[:20])
    test = EpisodeArrays.of(held_out[20:])
    names = tuple(demos[0].channel_names)

    print("training the default (fast) configuration ...", flush=True)
    start = time.perf_counter()
    fast = NeuralASM.fit(train.x, names, FAST, labels=train.skills, validation=validation.x)
    train_seconds = time.perf_counter() - start
    epoch_ms = train_seconds / FAST.epochs * 1e3

    print("timing the reference loop ...", flush=True)
    norm = fast.normaliser
    ref_ms = reference_epoch_ms(norm.normalise(train.x))

    stream = fast.stream("online")
    observations = test.x[0]
    start = time.perf_counter()
    repeats = 20
    for _ in range(repeats):
        stream = fast.stream("online")
        for x in observations:
            stream.step(x)
    step_ms = (time.perf_counter() - start) / (repeats * len(observations)) * 1e3

    print(f"training the default configuration with {args.seeds - 1} more seed(s) ...", flush=True)
    fast_models = [fast] + [
        NeuralASM.fit(train.x, names, FAST.with_(seed=FAST.seed + k), labels=train.skills, validation=validation.x)
        for k in range(1, args.seeds)
    ]

    print(f"training the faithful configuration ({args.faithful_epochs} epochs, batch 1) ...", flush=True)
    faithful = NeuralASM.fit(train.x, names, FAITHFUL.with_(epochs=args.faithful_epochs))

    xtr, xte = norm.normalise(train.x), norm.normalise(test.x)
    steps = xte.shape[1]
    recall_fast = [mse(m.normaliser.normalise(m.recall(test.x[:, :1], steps)), m.normaliser.normalise(test.x))
                   for m in fast_models]
    online_fast = [float((m.errors(test.x, "online")[:, 1:] ** 2).mean()) for m in fast_models]
    recall_faithful = faithful.normaliser.normalise(faithful.recall(test.x[:, :1], steps))
    skill_mean = StepStatistics.fit(xtr, train.skills).expected(xte)
    linear = LinearOneStep.fit(xtr)
    result = {
        "train_seconds": round(train_seconds, 2),
        "epochs": FAST.epochs,
        "epoch_ms": round(epoch_ms, 2),
        "reference_epoch_ms": round(ref_ms, 1),
        "speedup": round(ref_ms / epoch_ms, 1),
        "step_ms": round(step_ms, 3),
        "recall_mse_fast": round(float(np.mean(recall_fast)), 5),  # mean over training seeds
        "recall_mse_fast_per_seed": [round(v, 5) for v in recall_fast],
        "recall_mse_faithful": round(mse(recall_faithful, faithful.normaliser.normalise(test.x)), 5),
        "faithful_epochs": args.faithful_epochs,
        "recall_mse_skill_mean": round(mse(skill_mean, xte), 5),
        "recall_mse_linear_rollout": round(mse(linear.rollout(xte[:, :1], steps), xte), 5),
        "online_mse": round(float(np.mean(online_fast)), 5),
        "online_mse_per_seed": [round(v, 5) for v in online_fast],
        "online_mse_linear": round(mse(linear.expected(xte), xte), 5),
    }
    print(json.dumps(result))


if __name__ == "__main__":
    main()
