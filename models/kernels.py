"""Compiled kernels of the tPC: the Gauss-Newton relaxation of z and the spectral norm of W_F.

One Gauss-Newton step of one sequence is ~30 small array operations on vectors of 25 and 256
values; in numpy each costs ~1.5 us of dispatch, far more than its arithmetic. Compiled with
numba the whole relaxation of a sequence is one call (~20 us for the paper's sizes against
~100 us in numpy), and a batch is a loop over its sequences with the same arithmetic, so one
stream and 64 streams stepped together get the same z. The first call in a fresh install
compiles (~10 s); the machine code is cached beside this file (or in numba's user cache when
that folder is read-only).
"""

from __future__ import annotations

import numpy as np
from numba import njit

# Halvings of a Gauss-Newton step that would raise the energy before it is given up.
MAX_HALVINGS = 4


@njit(cache=True, fastmath=True)
def _tanh(x: np.ndarray) -> np.ndarray:
    """tanh of a float32 vector within 3e-7 of np.tanh: Eigen's rational approximation.

    Compiled code gets libm's scalar tanhf (~15 ns a value), ten times numpy's vectorised
    one; this polynomial ratio vectorises and is most of the kernel's speed on batches.
    """
    clamp = np.float32(7.90531110763549805)  # where the ratio reaches +-1 in float32
    a1, a3, a5 = np.float32(4.89352455891786e-03), np.float32(6.37261928875436e-04), np.float32(1.48572235717979e-05)
    a7, a9 = np.float32(5.12229709037114e-08), np.float32(-8.60467152213735e-11)
    a11, a13 = np.float32(2.00018790482477e-13), np.float32(-2.76076847742355e-16)
    b0, b2 = np.float32(4.89352518554385e-03), np.float32(2.26843463243900e-03)
    b4, b6 = np.float32(1.18534705686654e-04), np.float32(1.19825839466702e-06)
    out = np.empty_like(x)
    for i in range(x.shape[0]):
        v = min(max(x[i], -clamp), clamp)
        v2 = v * v
        p = v * ((((((a13 * v2 + a11) * v2 + a9) * v2 + a7) * v2 + a5) * v2 + a3) * v2 + a1)
        q = ((b6 * v2 + b4) * v2 + b2) * v2 + b0
        out[i] = p / q
    return out


@njit(cache=True, fastmath=True)
def _gram(j: np.ndarray) -> np.ndarray:
    """J J^T for J (D, H): the lower triangle's dot products, mirrored (half a matrix
    product's work, and vectorised: ~2.5x faster than BLAS at these sizes)."""
    size, hidden = j.shape
    out = np.empty((size, size), np.float32)
    for r in range(size):
        for c in range(r + 1):
            acc = np.float32(0.0)
            for k in range(hidden):
                acc += j[r, k] * j[c, k]
            out[r, c] = acc
            out[c, r] = acc
    return out


@njit(cache=True)
def spectral_norm(w: np.ndarray) -> float:
    """||w||_2: the square root of the largest eigenvalue of the smaller Gram matrix."""
    if w.shape[0] > w.shape[1]:
        w = np.ascontiguousarray(w.T)
    return float(np.sqrt(max(np.linalg.eigvalsh(_gram(w).astype(np.float64))[-1], 0.0)))


@njit(cache=True)
def _cholesky_solve(factor: np.ndarray, b: np.ndarray) -> np.ndarray:
    """x with (L L^T) x = b for the lower Cholesky factor L: two triangular substitutions."""
    n = b.shape[0]
    y = np.empty_like(b)
    for i in range(n):
        acc = b[i]
        for k in range(i):
            acc -= factor[i, k] * y[k]
        y[i] = acc / factor[i, i]
    for i in range(n - 1, -1, -1):
        acc = y[i]
        for k in range(i + 1, n):
            acc -= factor[k, i] * y[k]
        y[i] = acc / factor[i, i]
    return y


@njit(cache=True, nogil=True)  # the service's event loop runs on while a batch relaxes
def gauss_newton(prior: np.ndarray, x: np.ndarray, w_f: np.ndarray, scale: np.ndarray, steps: int) -> np.ndarray:
    """z after ``steps`` chord Gauss-Newton steps on F = ||z - prior||^2 + ||Pi^1/2 (x - W_F f(z))||^2
    for every row of prior (B, H) and x (B, D), given W_F (D, H) and scale = Pi^1/2 (D,), float32.

    See ``TemporalPC.infer`` for the method; a step that would raise F is halved up to
    ``MAX_HALVINGS`` times and then given up, so F never increases.
    """
    batch = prior.shape[0]
    one, half = np.float32(1.0), np.float32(0.5)
    w = w_f * scale.reshape(-1, 1)  # Pi^1/2 W_F
    target = x * scale
    identity = np.eye(w.shape[0], dtype=np.float32)
    out = np.empty_like(prior)
    for b in range(batch):
        origin = prior[b]
        z = origin.copy()
        fz = _tanh(z)
        residual = target[b] - np.dot(w, fz)
        energy = np.dot(residual, residual)
        slope = one - fz * fz  # f'(prior): every step's curvature is evaluated here (the chord method)
        factor = np.linalg.cholesky(_gram(w * slope) + identity)  # I + J J^T
        for _ in range(steps):
            grad = (z - origin) - (one - fz * fz) * np.dot(residual, w)
            dz = grad - slope * np.dot(_cholesky_solve(factor, np.dot(w, slope * grad)), w)
            for _ in range(MAX_HALVINGS + 1):
                new_z = z - dz
                new_fz = _tanh(new_z)
                new_residual = target[b] - np.dot(w, new_fz)
                moved = new_z - origin
                new_energy = np.dot(moved, moved) + np.dot(new_residual, new_residual)
                if new_energy <= energy:
                    z, fz, residual, energy = new_z, new_fz, new_residual, new_energy
                    break
                dz *= half
        out[b] = z
    return out


def compile_now() -> None:
    """Compile the kernels (or load them from the cache) before they are needed, so that a
    service's first step does not wait for the compiler."""
    w = np.ones((2, 3), np.float32)
    gauss_newton(np.zeros((1, 3), np.float32), np.zeros((1, 2), np.float32), w, np.ones(2, np.float32), 1)
    spectral_norm(w)
