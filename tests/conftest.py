import runtime  # noqa: F401  (first: one BLAS thread, no display)

import numpy as np
import pytest
import torch

from models.asm import NeuralASM
from models.config import FAST
from models.synthetic import make_skills, split

torch.set_num_threads(1)

# Small but real: three skills, distinct starts, noisy repetitions.
SMALL = FAST.with_(hidden_size=96, epochs=250)


@pytest.fixture(scope="session")
def skills():
    return split(make_skills(n_skills=3, repetitions=12, steps=15, channels=10, seed=3), 2)


@pytest.fixture(scope="session")
def trained(skills):
    train, _ = skills
    return NeuralASM.fit(train.data, train.channel_names, SMALL, progress=False)


@pytest.fixture
def rng():
    return np.random.default_rng(0)
