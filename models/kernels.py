"""Compiled kernels of the tPC: the Gauss-Newton relaxation of z, the spectral norm of W_F and the
Adam update of the weights.

One Gauss-Newton step of one sequence is ~30 small array operations on vectors of 25 and 256
values, whose dispatch in numpy costs more than their arithmetic. Compiled with numba the
whole relaxation of a sequence is one call, and a batch is a loop over its sequences, each relaxed alone by explicit
loops (no BLAS or LAPACK call, whose checks and copies cost more than the arithmetic at these
sizes), so one stream and 64 streams stepped together get the same z. The kernels use numba's
numpy error model: the default checks every division for zero, which keeps loops with a
division from vectorising. The first call in a fresh install compiles; the machine
code is cached beside this file (or in numba's user cache when that folder is read-only).
"""

from __future__ import annotations

import numpy as np
from numba import njit

# Halvings of a Gauss-Newton step that would raise the energy before it is given up.
MAX_HALVINGS = 4


@njit(cache=True, fastmath=True, error_model="numpy")
def _tanh(x: np.ndarray, out: np.ndarray) -> None:
    """out = tanh(x) for float32 vectors, within 3e-7 of np.tanh: Eigen's rational approximation.

    Compiled code gets libm's scalar tanhf, which does not vectorise; this polynomial ratio does.
    """
    clamp = np.float32(7.90531110763549805)  # where the ratio reaches +-1 in float32
    a1, a3, a5 = np.float32(4.89352455891786e-03), np.float32(6.37261928875436e-04), np.float32(1.48572235717979e-05)
    a7, a9 = np.float32(5.12229709037114e-08), np.float32(-8.60467152213735e-11)
    a11, a13 = np.float32(2.00018790482477e-13), np.float32(-2.76076847742355e-16)
    b0, b2 = np.float32(4.89352518554385e-03), np.float32(2.26843463243900e-03)
    b4, b6 = np.float32(1.18534705686654e-04), np.float32(1.19825839466702e-06)
    for i in range(x.shape[0]):
        v = min(max(x[i], -clamp), clamp)
        v2 = v * v
        p = v * ((((((a13 * v2 + a11) * v2 + a9) * v2 + a7) * v2 + a5) * v2 + a3) * v2 + a1)
        q = ((b6 * v2 + b4) * v2 + b2) * v2 + b0
        out[i] = p / q


@njit(cache=True, fastmath=True, error_model="numpy")
def _gram(j: np.ndarray, out: np.ndarray) -> None:
    """out = J J^T for J (D, H): the lower triangle's dot products, mirrored, two rows by two
    columns at a time so that each value loaded serves two products (half a matrix product's
    work, vectorised, without BLAS's per-call checks)."""
    size, hidden = j.shape
    for r in range(0, size, 2):
        r2 = min(r + 1, size - 1)  # an odd last row pairs with itself
        for c in range(0, r2 + 1, 2):
            c2 = min(c + 1, size - 1)
            a, b, d, e = np.float32(0.0), np.float32(0.0), np.float32(0.0), np.float32(0.0)
            for k in range(hidden):
                a += j[r, k] * j[c, k]
                b += j[r, k] * j[c2, k]
                d += j[r2, k] * j[c, k]
                e += j[r2, k] * j[c2, k]
            out[r, c], out[c, r], out[r, c2], out[c2, r] = a, a, b, b
            out[r2, c], out[c, r2], out[r2, c2], out[c2, r2] = d, d, e, e


@njit(cache=True)
def spectral_norm(w: np.ndarray) -> float:
    """||w||_2: the square root of the largest eigenvalue of the smaller Gram matrix."""
    if w.shape[0] > w.shape[1]:
        w = np.ascontiguousarray(w.T)
    gram = np.empty((w.shape[0], w.shape[0]), np.float32)
    _gram(w, gram)
    return float(np.sqrt(max(np.linalg.eigvalsh(gram.astype(np.float64))[-1], 0.0)))


@njit(cache=True, fastmath=True, error_model="numpy")
def _cholesky(a: np.ndarray) -> None:
    """The lower Cholesky factor of a symmetric positive definite a (n, n), in place in its lower
    triangle. At n = 25 a LAPACK call's checks and copies cost more than its arithmetic."""
    n = a.shape[0]
    for j in range(n):
        acc = a[j, j]
        for k in range(j):
            acc -= a[j, k] * a[j, k]
        pivot = np.sqrt(acc)
        a[j, j] = pivot
        for i in range(j + 1, n):
            acc = a[i, j]
            for k in range(j):
                acc -= a[i, k] * a[j, k]
            a[i, j] = acc / pivot


@njit(cache=True, fastmath=True, error_model="numpy")
def _cholesky_solve(factor: np.ndarray, b: np.ndarray) -> None:
    """b <- x with (L L^T) x = b for the lower Cholesky factor L, in place: two substitutions."""
    n = b.shape[0]
    for i in range(n):
        acc = b[i]
        for k in range(i):
            acc -= factor[i, k] * b[k]
        b[i] = acc / factor[i, i]
    for i in range(n - 1, -1, -1):
        acc = b[i]
        for k in range(i + 1, n):
            acc -= factor[k, i] * b[k]
        b[i] = acc / factor[i, i]


@njit(cache=True, fastmath=True, error_model="numpy")
def _residual(w: np.ndarray, fz: np.ndarray, target: np.ndarray, out: np.ndarray) -> float:
    """out = target - w f(z) for w (D, H); returns ||out||^2."""
    total = np.float32(0.0)
    for d in range(w.shape[0]):
        acc = np.float32(0.0)
        for k in range(w.shape[1]):
            acc += w[d, k] * fz[k]
        out[d] = target[d] - acc
        total += out[d] * out[d]
    return total


@njit(cache=True, nogil=True, fastmath=True, error_model="numpy")  # nogil: the service's event loop runs on while a batch relaxes
def gauss_newton(prior: np.ndarray, x: np.ndarray, w_f: np.ndarray, scale: np.ndarray, steps: int) -> np.ndarray:
    """z after ``steps`` chord Gauss-Newton steps on F = ||z - prior||^2 + ||Pi^1/2 (x - W_F f(z))||^2
    for every row of prior (B, H) and x (B, D), given W_F (D, H) and scale = Pi^1/2 (D,), float32.

    See ``TemporalPC.infer`` for the method; a step that would raise F is halved up to
    ``MAX_HALVINGS`` times and then given up, so F never increases. Each row is relaxed
    alone by explicit loops over preallocated buffers (no BLAS or LAPACK call, no
    allocation per row): a row's arithmetic does not depend on the batch around it.
    """
    batch, hidden = prior.shape
    size = w_f.shape[0]
    one, half = np.float32(1.0), np.float32(0.5)
    w = w_f * scale.reshape(-1, 1)  # Pi^1/2 W_F
    j = np.empty_like(w)  # J = Pi^1/2 W_F diag(f'(prior))
    factor = np.empty((size, size), np.float32)
    rows = np.empty((8, hidden), np.float32)  # per-row buffers, reused
    z, fz, slope, grad, dz, new_z, new_fz, origin = rows[0], rows[1], rows[2], rows[3], rows[4], rows[5], rows[6], rows[7]
    small = np.empty((4, size), np.float32)
    target, residual, new_residual, solution = small[0], small[1], small[2], small[3]
    out = np.empty_like(prior)
    for b in range(batch):  # copies by explicit loops: an array expression allocates, a slice counts references
        for d in range(size):
            target[d] = x[b, d] * scale[d]
        for k in range(hidden):
            origin[k] = z[k] = prior[b, k]
        _tanh(z, fz)
        energy = _residual(w, fz, target, residual)
        for k in range(hidden):  # f'(prior): every step's curvature is evaluated here (the chord method)
            slope[k] = one - fz[k] * fz[k]
        for d in range(size):
            for k in range(hidden):
                j[d, k] = w[d, k] * slope[k]
        _gram(j, factor)
        for d in range(size):
            factor[d, d] += one  # I + J J^T
        _cholesky(factor)
        for _ in range(steps):
            # grad = (z - prior) - f'(z) (eps W); J^T-space solve: dz = grad - J^T (I + J J^T)^-1 J grad
            for k in range(hidden):
                grad[k] = np.float32(0.0)
            for d in range(size):
                coef = residual[d]
                for k in range(hidden):
                    grad[k] += coef * w[d, k]
            for k in range(hidden):
                grad[k] = (z[k] - origin[k]) - (one - fz[k] * fz[k]) * grad[k]
            for d in range(size):
                acc = np.float32(0.0)
                for k in range(hidden):
                    acc += j[d, k] * grad[k]
                solution[d] = acc
            _cholesky_solve(factor, solution)
            for k in range(hidden):
                dz[k] = grad[k]
            for d in range(size):
                coef = solution[d]
                for k in range(hidden):
                    dz[k] -= coef * j[d, k]
            for _ in range(MAX_HALVINGS + 1):
                moved = np.float32(0.0)
                for k in range(hidden):
                    new_z[k] = z[k] - dz[k]
                    gap = new_z[k] - origin[k]
                    moved += gap * gap
                _tanh(new_z, new_fz)
                new_energy = moved + _residual(w, new_fz, target, new_residual)
                if new_energy <= energy:
                    for k in range(hidden):
                        z[k], fz[k] = new_z[k], new_fz[k]
                    for d in range(size):
                        residual[d] = new_residual[d]
                    energy = new_energy
                    break
                for k in range(hidden):
                    dz[k] *= half
        for k in range(hidden):
            out[b, k] = z[k]
    return out


@njit(cache=True, fastmath=True, error_model="numpy")
def adam_step(weight: np.ndarray, grad: np.ndarray, mean: np.ndarray, square: np.ndarray, rate: float, step: int) -> None:
    """One Adam update of ``weight`` in place, torch.optim.Adam's rule: betas 0.9 and 0.999,
    bias-corrected moments ``mean`` and ``square``, eps 1e-8 outside the square root, no weight
    decay; ``step`` counts from 1. All arrays C-contiguous float32 of one shape."""
    w, g, m, v = weight.ravel(), grad.ravel(), mean.ravel(), square.ravel()
    beta1, beta2, eps, one = np.float32(0.9), np.float32(0.999), np.float32(1e-8), np.float32(1.0)
    step_size = np.float32(rate / (1.0 - 0.9**step))
    root_bias = np.float32(np.sqrt(1.0 - 0.999**step))
    for i in range(w.size):
        m[i] = beta1 * m[i] + (one - beta1) * g[i]
        v[i] = beta2 * v[i] + (one - beta2) * g[i] * g[i]
        w[i] -= step_size * m[i] / (np.sqrt(v[i]) / root_bias + eps)


def compile_now() -> None:
    """Compile the kernels (or load them from the cache) before they are needed, so that a
    service's first step does not wait for the compiler."""
    w = np.ones((2, 3), np.float32)
    gauss_newton(np.zeros((1, 3), np.float32), np.zeros((1, 2), np.float32), w, np.ones(2, np.float32), 1)
    spectral_norm(w)
    adam_step(w, w.copy(), w.copy(), w.copy(), 1e-3, 1)
