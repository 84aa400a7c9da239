import neural_asm.runtime  # noqa: F401  (first: one BLAS thread, no display)

from pathlib import Path

import numpy as np
import pytest

HERE = Path(__file__).resolve().parent


# The probes' tests train and score networks: they run with the suite's slow tests, and the fast
# lane (``-m "not slow"``) does not even import them (the probes import the experiments).


def pytest_ignore_collect(collection_path: Path, config: pytest.Config) -> bool | None:
    if HERE in collection_path.parents and config.getoption("markexpr") == "not slow":
        return True
    return None


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    for item in items:
        if HERE in item.path.parents:
            item.add_marker(pytest.mark.slow)


@pytest.fixture
def rng():
    return np.random.default_rng(0)
