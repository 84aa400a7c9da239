import neural_asm.runtime  # noqa: F401  (first: one BLAS thread, no display)

import numpy as np
import pytest


@pytest.fixture
def rng():
    return np.random.default_rng(0)
