"""The block Cholesky factor of a symmetric positive definite matrix in block-band
storage (``band[i, k] = H[i, i - k]``, ``(B, w + 1, 7, 7)``;
:mod:`linkopt._engine.banded` assembles ``JᵀJ`` into it): :func:`factor` (one
``lax.scan`` step per block row, the carry the ``7w x 7w`` triangle of the ``w`` rows
before), :func:`forward` and :func:`backward` substitution (one scan each),
:func:`cho_solve`, :func:`matvec`.
``O(B w² 7³)`` work and ``O(B w)`` memory."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from . import dense

Band = Float[Array, "B w1 7 7"]


def factor(band: Band, damping) -> Band:
    """The lower block Cholesky factor of ``band + damping I`` in the same storage
    (``L[i, 0]`` the diagonal block, lower triangular; NaN from a non-positive pivot
    on, as :func:`linkopt._engine.dense.cholesky`)."""
    w = band.shape[1] - 1
    eye = jnp.eye(7, dtype=band.dtype)

    def row(window, blocks):  # window: L of the w rows before, (7w, 7w)
        a_row = jnp.concatenate([blocks[k] for k in range(w, 0, -1)], axis=1)
        l_row = dense.solve_lower(window, a_row.T).T  # (7, 7w): L[i, i-w .. i-1]
        l_ii = dense.cholesky(blocks[0] + damping * eye - l_row @ l_row.T)
        top = jnp.concatenate([window[7:, 7:], jnp.zeros((7 * w - 7, 7))], axis=1)
        bottom = jnp.concatenate([l_row[:, 7:], l_ii], axis=1)
        out = [l_ii] + [
            l_row[:, 7 * (w - k) : 7 * (w - k + 1)] for k in range(1, w + 1)
        ]
        return jnp.concatenate([top, bottom], axis=0), jnp.stack(out)

    _, lower = jax.lax.scan(row, jnp.eye(7 * w, dtype=band.dtype), band)
    return lower


def forward(lower: Band, b: Float[Array, "B 7"]) -> Float[Array, "B 7"]:
    """``y`` with ``L y = b`` (one scan down the band)."""
    w = lower.shape[1] - 1

    def step(previous, item):  # previous: y of rows i-w .. i-1
        blocks, rhs = item
        rhs = rhs - jnp.einsum("kab,kb->a", blocks[1:], previous[::-1])
        y = dense.solve_lower(blocks[0], rhs)
        return jnp.concatenate([previous[1:], y[None]]), y

    _, y = jax.lax.scan(step, jnp.zeros((w, 7), dtype=b.dtype), (lower, b))
    return y


def backward(lower: Band, y: Float[Array, "B 7"]) -> Float[Array, "B 7"]:
    """``x`` with ``Lᵀ x = y`` (one scan up the band)."""
    w = lower.shape[1] - 1

    def step(pending, item):  # pending[m]: what rows i-m owe to later rows
        blocks, rhs = item
        x = dense.solve_lower_transpose(blocks[0], rhs - pending[0])
        owed = jnp.einsum("kba,b->ka", blocks[1:], x)  # rows i-1 .. i-w
        shifted = jnp.concatenate([pending[1:], jnp.zeros((1, 7), dtype=y.dtype)])
        return shifted + owed, x

    _, x = jax.lax.scan(
        step, jnp.zeros((w, 7), dtype=y.dtype), (lower, y), reverse=True
    )
    return x


def cho_solve(lower: Band, b: Float[Array, "B 7"]) -> Float[Array, "B 7"]:
    """``x`` with ``L Lᵀ x = b`` for the factor of :func:`factor`."""
    return backward(lower, forward(lower, b))


def matvec(band: Band, x: Float[Array, "B 7"]) -> Float[Array, "B 7"]:
    """``H x`` for ``H`` in band storage (the lower band and its transpose)."""
    nb, w = band.shape[0], band.shape[1] - 1
    rows = np.arange(nb)[:, None] - np.arange(w + 1)[None, :]  # (B, w+1): i - k
    valid = jnp.asarray(rows >= 0)[..., None]
    padded = jnp.where(valid, x[np.maximum(rows, 0)], 0.0)  # x[i - k]
    out = jnp.einsum("ikab,ikb->ia", band, padded)
    upper = jnp.einsum("ikba,ib->ika", band[:, 1:], x)  # to row i - k, k >= 1
    return out.at[np.maximum(rows[:, 1:], 0)].add(jnp.where(valid[:, 1:], upper, 0.0))
