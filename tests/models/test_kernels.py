"""The hand-written pieces of the compiled relaxation against numpy's own, directly."""

import numpy as np
import pytest

from neural_asm.models.kernels import _cholesky, _cholesky_solve, _gram, _tanh


def test_rational_tanh_is_within_3e_7_of_numpy_and_saturates():
    x = np.concatenate([np.linspace(-12, 12, 20_001), [0.0, 1e-8, -1e-8, 7.9, -7.9, 50.0, -50.0]]).astype(np.float32)
    out = np.empty_like(x)
    _tanh(x, out)
    assert np.abs(out - np.tanh(x.astype(np.float64))).max() < 3e-7
    assert out[x == 0.0] == 0.0 and np.all(np.abs(out) <= 1.0)
    np.testing.assert_array_equal(np.sign(out[x != 0]), np.sign(x[x != 0]))


@pytest.mark.parametrize("n", [1, 2, 7, 25])
def test_cholesky_factor_and_solve_match_numpy(n):
    rng = np.random.default_rng(n)
    m = rng.normal(size=(n, n + 3)).astype(np.float32)
    a = (np.eye(n) + m @ m.T).astype(np.float32)  # I + J J^T, the shape of the relaxation's curvature
    factor = a.copy()
    _cholesky(factor)
    lower = np.tril(factor)
    np.testing.assert_allclose(lower, np.linalg.cholesky(a.astype(np.float64)), rtol=1e-4, atol=1e-5)
    b = rng.normal(size=n).astype(np.float32)
    x = b.copy()
    _cholesky_solve(factor, x)
    np.testing.assert_allclose(x, np.linalg.solve(a.astype(np.float64), b), rtol=1e-4, atol=1e-5)


@pytest.mark.parametrize("shape", [(25, 256), (7, 5), (1, 3)])
def test_gram_is_the_matrix_product(shape):
    j = np.random.default_rng(0).normal(size=shape).astype(np.float32)
    out = np.full((shape[0], shape[0]), np.nan, np.float32)
    _gram(j, out)
    np.testing.assert_allclose(out, j.astype(np.float64) @ j.T.astype(np.float64), rtol=1e-4, atol=1e-4)
