"""A built-in multi-skill dataset: smooth trajectories with noisy repetitions.

Each skill is a set of slow sinusoids per channel with its own phases and offsets, so
skills start from distinct observations. Repetitions differ by amplitude and timing
jitter and sensor noise, like repeated demonstrations of one movement. It lets the
model be trained and checked without the simulator.
"""

from __future__ import annotations

import numpy as np

from neural_asm.models.sequences import Sequences


def make_skills(
    n_skills: int = 3,
    repetitions: int = 10,
    steps: int = 15,
    channels: int = 12,
    jitter: float = 0.05,
    noise: float = 0.02,
    seed: int = 0,
) -> Sequences:
    rng = np.random.default_rng(seed)
    phase = np.linspace(0.0, 1.0, steps)
    sequences, labels = [], []
    for skill in range(n_skills):
        freq = rng.uniform(0.3, 1.2, channels)
        offset = rng.uniform(-1.0, 1.0, channels)
        amplitude = rng.uniform(0.3, 1.0, channels)
        start = rng.uniform(0, 2 * np.pi, channels)
        for _ in range(repetitions):
            gain = 1.0 + jitter * rng.standard_normal(channels)
            shift = jitter * rng.standard_normal()
            t = phase[:, None] + shift
            clean = offset + amplitude * gain * np.sin(2 * np.pi * freq * t + start)
            sequences.append(clean + noise * rng.standard_normal(clean.shape))
            labels.append(skill)
    names = tuple(f"ch{i}" for i in range(channels))
    return Sequences(np.array(sequences), np.array(labels), names, provenance={"source": "synthetic", "seed": seed})


def split(data: Sequences, held_out_per_skill: int) -> tuple[Sequences, Sequences]:
    """Hold out the last repetitions of every skill."""
    test = np.zeros(len(data), bool)
    for skill in np.unique(data.labels):
        test[np.flatnonzero(data.labels == skill)[-held_out_per_skill:]] = True
    return data.take(~test), data.take(test)
