import neural_asm.runtime  # noqa: F401  (first: one BLAS thread, no display)

import os
import shutil
import tempfile
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from neural_asm.models import checkpoint
from neural_asm.models.asm import NeuralASM
from neural_asm.models.config import FAST
from neural_asm.models.synthetic import make_skills, split
from neural_asm.sim.channels import CHANNEL_NAMES
from small_config import SMALL


def pytest_configure(config: pytest.Config) -> None:
    """Tests never touch the user's data home (read by the commands' defaults when their modules load)."""
    os.environ["NASM_HOME"] = tempfile.mkdtemp(prefix="nasm-home-")


def pytest_unconfigure(config: pytest.Config) -> None:
    shutil.rmtree(os.environ.get("NASM_HOME", ""), ignore_errors=True)


# Small but real: three skills, distinct starts, noisy repetitions.


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
def small_panda_model() -> NeuralASM:
    """A small network trained on simulated Panda episodes (4 per skill), calibrated in both
    recall modes on others: the model the client tests serve."""
    from neural_asm.sim.paper import run_episode
    from neural_asm.sim.skills import SKILLS

    def episodes(seeds: range) -> np.ndarray:
        return np.stack([run_episode(s, seed).observations for s in SKILLS for seed in seeds])

    demos, precision, thresholds = episodes(range(4)), episodes(range(10, 15)), episodes(range(20, 25))
    model = NeuralASM.fit(demos, CHANNEL_NAMES, FAST.with_(hidden_size=64, epochs=150), progress=False)
    for mode in ("offline", "online"):
        model.calibrate(precision, thresholds, mode, 1)
    return model


@pytest.fixture(scope="module")
def server(model_dir: Path, tmp_path_factory: pytest.TempPathFactory):
    """An embedded service on the requesting module's ``model_dir``."""
    from neural_asm.service.embedded import start_embedded
    from neural_asm.service.settings import Settings

    settings = Settings(models_dir=model_dir, recordings_dir=tmp_path_factory.mktemp("service-recordings"),
                        build_default_model=False)
    with start_embedded(settings) as srv:
        yield srv


@pytest.fixture(scope="session")
def servable_model(tmp_path_factory: pytest.TempPathFactory) -> Callable[..., Path]:
    """Make a service's model folder: a small network trained on synthetic 25-channel skills
    (the Panda's channel names) at ``rate_hz``, calibrated for ``modes``, its training episodes
    beside it as ``episodes.npy``."""
    def make(n_skills: int = 1, repetitions: int = 4, steps: int = 6, hidden_size: int = 16, epochs: int = 5,
             modes: tuple[str, ...] = ("offline",), name: str = "m", seed: int = 0, rate_hz: float = 2.0) -> Path:
        folder = tmp_path_factory.mktemp("models")
        data = make_skills(n_skills=n_skills, repetitions=repetitions, steps=steps, channels=len(CHANNEL_NAMES),
                           seed=seed)
        model = NeuralASM.fit(data.data, CHANNEL_NAMES, FAST.with_(hidden_size=hidden_size, epochs=epochs),
                              progress=False, rate_hz=rate_hz)
        for mode in modes:
            model.calibrate(data.data, data.data, mode, 1)
        checkpoint.save(model, folder / f"{name}.safetensors")
        np.save(folder / "episodes.npy", data.data)
        return folder

    return make


# Slow modules that build their cases when imported (schemathesis loads the OpenAPI schema of an
# app it trains a model for): not even collected when the slow tests are deselected.
BUILT_AT_IMPORT = {"test_service_fuzz.py"}


def pytest_ignore_collect(collection_path: Path, config: pytest.Config) -> bool | None:
    if collection_path.name in BUILT_AT_IMPORT and config.getoption("markexpr") == "not slow":
        return True
    return None
