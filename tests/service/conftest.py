"""The service tests' model: small, trained on synthetic Panda-shaped data (25 named channels)."""

from pathlib import Path

import numpy as np
import pytest

from neural_asm.models import checkpoint
from neural_asm.models.asm import NeuralASM


@pytest.fixture(scope="module")
def model_dir(servable_model) -> Path:
    return servable_model(n_skills=2, repetitions=8, steps=15, hidden_size=64, epochs=100,
                          modes=("offline", "online"), name="panda", seed=1)


@pytest.fixture(scope="module")
def episodes(model_dir: Path) -> np.ndarray:
    return np.load(model_dir / "episodes.npy")


@pytest.fixture(scope="module")
def reference(model_dir: Path) -> NeuralASM:
    return checkpoint.load(model_dir / "panda.safetensors")
