import runtime  # noqa: F401  (first: one BLAS thread, no display)

import os
import tempfile
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
import torch

from models import checkpoint
from models.asm import NeuralASM
from models.config import FAST
from models.synthetic import make_skills, split
from sim.channels import CHANNEL_NAMES

torch.set_num_threads(1)


def pytest_configure(config: pytest.Config) -> None:
    """Tests never touch the user's data home (read by the commands' defaults when their modules load)."""
    os.environ["NASM_HOME"] = tempfile.mkdtemp(prefix="nasm-home-")


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


@pytest.fixture(scope="session")
def servable_model(tmp_path_factory: pytest.TempPathFactory) -> Callable[..., Path]:
    """Make a service's model folder: a small network trained on synthetic 25-channel skills
    (the Panda's channel names), calibrated for ``modes``, its training episodes beside it
    as ``episodes.npy``."""
    def make(n_skills: int = 1, repetitions: int = 4, steps: int = 6, hidden_size: int = 16, epochs: int = 5,
             modes: tuple[str, ...] = ("offline",), name: str = "m", seed: int = 0) -> Path:
        folder = tmp_path_factory.mktemp("models")
        data = make_skills(n_skills=n_skills, repetitions=repetitions, steps=steps, channels=len(CHANNEL_NAMES),
                           seed=seed)
        model = NeuralASM.fit(data.data, CHANNEL_NAMES, FAST.with_(hidden_size=hidden_size, epochs=epochs),
                              progress=False)
        for mode in modes:
            model.calibrate(data.data, data.data, mode, 1)
        checkpoint.save(model, folder / f"{name}.safetensors")
        np.save(folder / "episodes.npy", data.data)
        return folder

    return make
