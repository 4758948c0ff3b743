"""The block Cholesky factor of a symmetric positive definite matrix in block-band
storage (``band[i, k] = H[i, i - k]``, ``(B, w + 1, 7, 7)``;
:mod:`linkopt._engine.banded` assembles ``JᵀJ`` into it): :func:`factor` (one
``lax.scan`` step per block row, the carry the ``7w x 7w`` triangle of the ``w`` rows
before), :func:`forward` and :func:`backward` substitution (one scan each),
:func:`cho_solve`, :func:`matvec`.
``O(B w² 7³)`` work and ``O(B w)`` memory.

Where linkopt's compiled kernels serve (:func:`linkopt._engine.dense.kernels_serve`:
float64 on the CPU, the extension built), :func:`factor`, :func:`forward`,
:func:`backward` and :func:`cho_solve` are one call of its ``band_factor`` or
``band_solve`` handler each (``dense.cc``: the same block algorithm as plain loops).
A scan step of XLA costs about a microsecond whatever it computes, and the scans take
one per block row: measured on lazy tongs of 1000 bodies (``w = 2``), the factor took
2.8 ms as a scan and 0.9 ms in the kernel, its two triangular solves 2.6 and 0.2-0.3
ms. The kernels agree with the scans here to round-off (``tests/test_band_kernels.py``);
their derivatives are the scans' (``jax.custom_jvp``), and ``LINKOPT_KERNELS=0`` (or no
extension, another platform or precision) runs the scans. The solve's handler takes a
factor without the right-hand sides' batch dimensions (``vmap_method="expand_dims"``),
so that solving for many columns of one factor (σ_min's inverse iteration,
:mod:`linkopt._engine.banded_sigma`) does not copy the factor once per column."""

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
    damping = jnp.asarray(damping, dtype=band.dtype)
    if dense.kernels_serve(band):
        return _kernel_factor(band, damping)
    return _plain_factor(band, damping)


def forward(lower: Band, b: Float[Array, "B 7"]) -> Float[Array, "B 7"]:
    """``y`` with ``L y = b`` (one scan down the band)."""
    if dense.kernels_serve(lower, b):
        return _KERNEL_SOLVES[0](lower, b)
    return _plain_forward(lower, b)


def backward(lower: Band, y: Float[Array, "B 7"]) -> Float[Array, "B 7"]:
    """``x`` with ``Lᵀ x = y`` (one scan up the band)."""
    if dense.kernels_serve(lower, y):
        return _KERNEL_SOLVES[1](lower, y)
    return _plain_backward(lower, y)


def cho_solve(lower: Band, b: Float[Array, "B 7"]) -> Float[Array, "B 7"]:
    """``x`` with ``L Lᵀ x = b`` for the factor of :func:`factor`."""
    if dense.kernels_serve(lower, b):
        return _KERNEL_SOLVES[2](lower, b)
    return _plain_backward(lower, _plain_forward(lower, b))


def _plain_factor(band: Band, damping) -> Band:
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


def _plain_forward(lower: Band, b: Float[Array, "B 7"]) -> Float[Array, "B 7"]:
    w = lower.shape[1] - 1

    def step(previous, item):  # previous: y of rows i-w .. i-1
        blocks, rhs = item
        rhs = rhs - jnp.einsum("kab,kb->a", blocks[1:], previous[::-1])
        y = dense.solve_lower(blocks[0], rhs)
        return jnp.concatenate([previous[1:], y[None]]), y

    _, y = jax.lax.scan(step, jnp.zeros((w, 7), dtype=b.dtype), (lower, b))
    return y


def _plain_backward(lower: Band, y: Float[Array, "B 7"]) -> Float[Array, "B 7"]:
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


_kernel_factor = dense.with_plain_derivative(
    lambda band, damping: dense.call_kernel("band_factor", band, band, damping),
    _plain_factor,
)


def _kernel_solve(mode: int, plain):
    """The ``band_solve`` handler in ``mode`` (0: ``L y = b``, 1: ``Lᵀ x = y``, 2:
    both), its derivative ``plain``'s."""

    def kernel(lower, b):
        return dense.call_kernel(
            "band_solve", b, lower, b, vmap_method="expand_dims", mode=np.int32(mode)
        )

    return dense.with_plain_derivative(kernel, plain)


_KERNEL_SOLVES = (
    _kernel_solve(0, _plain_forward),
    _kernel_solve(1, _plain_backward),
    _kernel_solve(2, lambda lower, b: _plain_backward(lower, _plain_forward(lower, b))),
)


def matvec(band: Band, x: Float[Array, "B 7"]) -> Float[Array, "B 7"]:
    """``H x`` for ``H`` in band storage (the lower band and its transpose)."""
    nb, w = band.shape[0], band.shape[1] - 1
    rows = np.arange(nb)[:, None] - np.arange(w + 1)[None, :]  # (B, w+1): i - k
    valid = jnp.asarray(rows >= 0)[..., None]
    padded = jnp.where(valid, x[np.maximum(rows, 0)], 0.0)  # x[i - k]
    out = jnp.einsum("ikab,ikb->ia", band, padded)
    upper = jnp.einsum("ikba,ib->ika", band[:, 1:], x)  # to row i - k, k >= 1
    return out.at[np.maximum(rows[:, 1:], 0)].add(jnp.where(valid[:, 1:], upper, 0.0))
