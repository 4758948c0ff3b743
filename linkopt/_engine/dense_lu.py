"""General square matrices in plain JAX (no LAPACK custom call, as
:mod:`linkopt._engine.dense`): LU with partial pivoting, a solve and the determinant.

* :func:`lu_factor` of an exactly singular matrix gives a zero pivot, and
  :func:`lu_solve` then inf/NaN, as LAPACK's ``getrs`` would; :func:`det` gives 0.
* :func:`solve` is a ``lax.custom_linear_solve``, so its JVP and transpose are further
  solves with the same factor; the factorisation itself is never differentiated.
  :func:`det` differentiates through the LU loop (its callers' matrices are at most
  6 × 6).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from jaxtyping import Array, Float, Int

from .. import _config  # noqa: F401  (float64 on before any array)
from .dense import solve_lower, solve_upper


def lu_factor(
    a: Float[Array, "n n"],
) -> tuple[Float[Array, "n n"], Int[Array, " n"], Float[Array, ""]]:
    """``(lu, perm, sign)``: ``a[perm] = L U`` with unit-lower ``L`` and ``U`` packed in
    ``lu`` (Doolittle, partial pivoting on the largest magnitude, ties to the lower
    row, as LAPACK's ``getrf``), and the permutation's sign."""
    n = a.shape[-1]
    rows = jnp.arange(n)

    def step(k, carry):
        m, perm, sign = carry
        col = jax.lax.dynamic_index_in_dim(m, k, 1, keepdims=False)
        p = jnp.argmax(jnp.where(rows >= k, jnp.abs(col), -1.0))
        swap = jnp.where(rows == k, p, jnp.where(rows == p, k, rows))
        m, perm = m[swap], perm[swap]
        sign = jnp.where(p == k, sign, -sign)
        col = jax.lax.dynamic_index_in_dim(m, k, 1, keepdims=False)
        row = jax.lax.dynamic_index_in_dim(m, k, 0, keepdims=False)
        pivot = jax.lax.dynamic_index_in_dim(col, k, 0, keepdims=False)
        # a zero pivot means a zero column below it: skip the elimination, as getrf
        factors = jnp.where(rows > k, col / jnp.where(pivot == 0.0, 1.0, pivot), 0.0)
        m = m - jnp.outer(factors, jnp.where(rows > k, row, 0.0))
        m = jax.lax.dynamic_update_index_in_dim(
            m, jnp.where(rows > k, factors, col), k, 1
        )
        return m, perm, sign

    return jax.lax.fori_loop(0, n, step, (a, rows, jnp.ones((), a.dtype)))


def lu_solve(lu, perm, b: Float[Array, "n ..."]):
    """``x`` with ``a x = b`` from :func:`lu_factor` (not differentiable in ``lu``).

    ``L``'s unit diagonal is written into ``lu`` rather than assumed: a solve with
    stored pivots of one runs in the compiled kernels (:func:`.dense.solve_lower`),
    where the assumed one ran the plain-JAX panels, several hundred operations per
    solve in each program (``y / 1`` is ``y``: without the kernels, the same
    numbers)."""
    unit = jnp.where(jnp.eye(lu.shape[-1], dtype=bool), 1.0, lu)
    return solve_upper(jnp.triu(lu), solve_lower(unit, b[perm]))


def solve(a: Float[Array, "n n"], b: Float[Array, "n ..."]):
    """``a⁻¹ b`` for a general square ``a`` by LU with partial pivoting;
    differentiable in both arguments (module docstring)."""
    fixed = jax.lax.stop_gradient(a)
    lu, perm, _ = lu_factor(fixed)

    def transpose_solve(_, rhs):  # traced only when a derivative is transposed
        lu_t, perm_t, _ = lu_factor(fixed.T)
        return lu_solve(lu_t, perm_t, rhs)

    return jax.lax.custom_linear_solve(
        lambda x: a @ x,
        b,
        solve=lambda _, rhs: lu_solve(lu, perm, rhs),
        transpose_solve=transpose_solve,
    )


def det(a: Float[Array, "n n"]) -> Float[Array, ""]:
    """Determinant: closed form up to 3 × 3 (exact zero at exact singularity, smooth
    derivatives), else the signed product of the LU pivots."""
    n = a.shape[-1]
    if n == 1:
        return a[0, 0]
    if n == 2:
        return a[0, 0] * a[1, 1] - a[0, 1] * a[1, 0]
    if n == 3:
        return jnp.dot(a[0], jnp.cross(a[1], a[2]))
    lu, _, sign = lu_factor(a)
    return sign * jnp.prod(jnp.diagonal(lu))
