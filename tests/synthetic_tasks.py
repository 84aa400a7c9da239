"""A small synthetic task whose truth is known: two skills whose trajectories depend on a 2-D
context (the rivals' tests and the context input's)."""

import numpy as np

T, D, C = 10, 8, 2  # steps, channels, context channels (the first C)


def varied_task(n_per_skill: int, seed: int, speed_spread: float = 0.0, noise: float = 0.05):
    """Two skills whose trajectories depend on a 2-D context (linearly and quadratically),
    optionally at a random speed per episode that the context does not give."""
    rng = np.random.default_rng(seed)
    shape = np.random.default_rng(123).standard_normal((2, 3, D - C))  # fixed task structure
    t = np.linspace(0.0, 1.0, T)[:, None]
    xs, skills = [], []
    for k, skill in enumerate(("reach", "push")):
        c = rng.uniform(-1.0, 1.0, (n_per_skill, C))
        speed = 1.0 + speed_spread * rng.uniform(-1.0, 1.0, n_per_skill)
        phase = speed[:, None, None] * t  # (n, T, 1)
        motion = (
            np.sin(2.5 * phase + shape[k, 0])
            + c[:, None, :1] * phase * shape[k, 1]
            + (c[:, None, 1:2] ** 2) * shape[k, 2]
        )
        x = np.empty((n_per_skill, T, D))
        x[:, :, :C] = c[:, None]  # context channels read the context
        x[:, :, C:] = motion
        xs.append(x + noise * rng.standard_normal(x.shape))
        skills += [skill] * n_per_skill
    return np.concatenate(xs), np.array(skills)
