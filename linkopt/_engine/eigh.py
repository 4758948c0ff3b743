"""The eigendecomposition of a small symmetric matrix in plain JAX (no LAPACK custom
call, as :mod:`linkopt._engine.dense`): cyclic Jacobi.

:func:`symmetric_eigh` runs a fixed number of sweeps (no convergence test, so it vmaps
without a ragged loop); on NaN input it returns NaN.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from .. import _config  # noqa: F401  (float64 on before any array)

#: Cyclic Jacobi sweeps of :func:`symmetric_eigh`. Convergence is quadratic once the
#: off-diagonal part is below the eigenvalue gaps; for 6 × 6 matrices 6 sweeps reach
#: round-off from random starts (``tests/test_dense.py``), 8 leave a margin.
JACOBI_SWEEPS = 8


def _rotation_pairs(k: int) -> np.ndarray:
    """``(k(k-1)/2, 2)``: the cyclic row-by-row order of Jacobi's ``(p, q)``, p < q."""
    return np.array([(p, q) for p in range(k) for q in range(p + 1, k)], dtype=int)


def _jacobi_rotation(app, aqq, apq):
    """``(c, s)`` of the rotation that zeroes ``a[p, q]`` (Golub & Van Loan,
    Alg. 8.5.1, ``|θ| ≤ π/4``; the identity where ``a[p, q]`` is already zero)."""
    safe = jnp.where(apq == 0.0, 1.0, apq)
    theta = (aqq - app) / (2.0 * safe)
    t = jnp.sign(theta) / (jnp.abs(theta) + jnp.sqrt(theta * theta + 1.0))
    t = jnp.where((apq == 0.0) | (theta == 0.0), jnp.where(apq == 0, 0.0, 1.0), t)
    c = 1.0 / jnp.sqrt(t * t + 1.0)
    return c, t * c


def _rotated_columns(m, p, q, c, s, index):
    """``m G`` for the Jacobi rotation ``G`` in the plane ``(p, q)``: only columns
    ``p`` and ``q`` change."""
    col_p = jax.lax.dynamic_index_in_dim(m, p, 1, keepdims=False)
    col_q = jax.lax.dynamic_index_in_dim(m, q, 1, keepdims=False)
    new_p, new_q = (c * col_p - s * col_q)[:, None], (s * col_p + c * col_q)[:, None]
    return jnp.where(index == p, new_p, jnp.where(index == q, new_q, m))


def symmetric_eigh(
    a: Float[Array, "k k"], sweeps: int = JACOBI_SWEEPS
) -> tuple[Float[Array, " k"], Float[Array, "k k"]]:
    """``(w, v)`` with ``a v = v diag(w)``, ``w`` ascending, for a small symmetric
    ``a`` (cyclic Jacobi, ``sweeps`` fixed sweeps).

    One loop step per rotation, which updates only rows and columns ``p`` and ``q``
    (``m ← Gᵀ m G`` as ``(m G)ᵀ G`` of the symmetric ``m``, ``v ← v G``). Forming
    ``G`` and taking three ``k x k`` matrix products a step made σ_min's Ritz step
    most of a sample step (``benchmarks/bench_evaluation.py``); unrolling a sweep's
    rotations with static ``(p, q)`` ran no faster inside the evaluation and compiled
    slower."""
    k = a.shape[-1]
    if k == 1:
        return a[0], jnp.ones_like(a)
    pairs = jnp.asarray(_rotation_pairs(k))
    index = jnp.arange(k)[None, :]

    def rotate(r, carry):
        m, v = carry
        p, q = pairs[r % pairs.shape[0], 0], pairs[r % pairs.shape[0], 1]
        row_p = jax.lax.dynamic_index_in_dim(m, p, 0, keepdims=False)
        row_q = jax.lax.dynamic_index_in_dim(m, q, 0, keepdims=False)
        c, s = _jacobi_rotation(row_p[p], row_q[q], row_p[q])
        m = _rotated_columns(m, p, q, c, s, index)  # m G
        m = _rotated_columns(m.T, p, q, c, s, index)  # Gᵀ m G (symmetric m)
        return m, _rotated_columns(v, p, q, c, s, index)

    m, v = jax.lax.fori_loop(
        0, sweeps * pairs.shape[0], rotate, (a, jnp.eye(k, dtype=a.dtype))
    )
    w = jnp.diagonal(m)
    order = jnp.argsort(w)
    return w[order], v[:, order]
