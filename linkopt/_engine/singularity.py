"""Proximity to forward and backward singularities (paper eq. 3).

``f_sing(s) = 1/σ_min(∂C_FK/∂s) + 1/σ_min(∂C_BK/∂s)`` on the homogenised system. The
Jacobians are tall when a loop is planar but written in 3-D (redundant rows); σ_min is
then the smallest of the ``n`` column-rank singular values, ``n = |s|``.

The motor and output rows' Jacobians do not depend on the motor/output *targets*
(the wrapped difference has unit slope), so both Jacobians are functions of ``s`` only.

σ_min is found by block inverse iteration with a Rayleigh–Ritz step on ``A = JᵀJ``
(``BLOCK`` vectors, ``ITERATIONS`` sweeps, a fixed seeded start block) instead of a full
SVD, because the LAPACK SVD of a few dozen columns would be most of a design
evaluation's time (``benchmarks/bench_evaluation.py`` times the evaluation).
``tests/test_singularity.py`` checks it against the SVD, also along a five-bar path
whose two smallest singular values come within 0.7 % of each other. ``A⁻¹ = L⁻ᵀL⁻¹`` is
formed once from the Cholesky factor (one triangular solve with ``n`` right-hand sides)
and each sweep is a matrix product rather than two batched triangular solves, which
would be most of σ_min's cost. Close to a singularity the smallest eigenvalue separates
and the iteration converges faster. The value returned is ``σ = ‖J(s) v‖`` with the
Ritz vector ``v`` held fixed, an upper bound on σ_min that equals it at convergence, and
whose derivative is the exact first derivative of σ_min for a simple smallest singular
value (``dσ = uᵀ dJ v``, ``u = Jv/σ``).

The Cholesky factor, its inverse and the ``BLOCK × BLOCK`` Ritz eigenproblem (cyclic
Jacobi) come from :mod:`linkopt._engine.dense`, not LAPACK: jaxlib's batched LAPACK
kernels can deadlock XLA's thread pool (:mod:`linkopt._config`). Where linkopt's
compiled kernels are in use, every step after the Gram matrix is one kernel call
(:func:`linkopt._engine.dense.smallest_right`), which applies ``A⁻¹`` by the two
triangular solves with the factor rather than forming it: the same in exact
arithmetic, equal to round-off (``tests/test_kernels.py``; σ to 1e-12 relative), and
its derivative is the plain-JAX steps'.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from .._config import jit, traced
from .._errors import InputError
from . import dense, eigh, jacobian, programs
from .blocks import in_blocks
from .geometry import Geometry, design_array, design_vector, geometry
from .model import Mechanism


def stacked_jacobians(mech: Mechanism, geom: Geometry, state) -> Float[Array, "2 m n"]:
    """``[∂C_FK/∂s, ∂C_BK/∂s]`` at ``state`` (homogenised), from the closed-form block
    Jacobians of :mod:`linkopt._engine.jacobian` (differentiable in state and
    design)."""
    return jacobian.stacked_jacobians(mech, geom, state)


BLOCK = 6
ITERATIONS = 6


def _orthonormalise(x: Float[Array, "B n k"]) -> Float[Array, "B n k"]:
    """Gram–Schmidt, each projection done twice, on the ``k`` columns of each block
    (inverse iteration makes the columns nearly parallel, so Cholesky QR would fail)."""
    columns = []
    for j in range(x.shape[-1]):
        v = x[:, :, j]
        for _ in range(2):
            for q in columns:
                v = v - jnp.sum(q * v, axis=1, keepdims=True) * q
        columns.append(v / jnp.sqrt(jnp.sum(v**2, axis=1, keepdims=True) + 1e-300))
    return jnp.stack(columns, axis=-1)


#: The Cholesky factor is of ``A + SHIFT·trace(A)·I`` (``A`` may be singular).
SHIFT = 1e-13


def plain_smallest(a: Float[Array, "B n n"], start: Float[Array, "B n k"]):
    """:func:`smallest_right_vectors` from the Gram matrices ``a = JᵀJ`` and the start
    blocks, in plain JAX operations."""
    n = a.shape[-1]
    shift = SHIFT * jnp.trace(a, axis1=1, axis2=2)[:, None, None] * jnp.eye(n)
    inv_lower = jax.vmap(lambda m: dense.lower_inverse(dense.cholesky(m)))(a + shift)
    inverse = jnp.einsum("bki,bkj->bij", inv_lower, inv_lower)  # A⁻¹ = L⁻ᵀ L⁻¹
    x = _orthonormalise(start)

    def sweep(_, x):
        return _orthonormalise(jnp.einsum("bij,bjk->bik", inverse, x))

    x = jax.lax.fori_loop(0, ITERATIONS, sweep, x)
    _, ritz = jax.vmap(eigh.symmetric_eigh)(jnp.einsum("bni,bnm,bmj->bij", x, a, x))
    return jnp.einsum("bnk,bk->bn", x, ritz[:, :, 0])


@jax.custom_jvp
def _kernel_smallest(a: Float[Array, "B n n"], start: Float[Array, "B n k"]):
    """:func:`plain_smallest` in one call of the compiled kernel, with its
    derivative."""
    return dense.smallest_right(
        a,
        start,
        iterations=ITERATIONS,
        sweeps=eigh.JACOBI_SWEEPS,
        shift=SHIFT,
    )


_kernel_smallest.defjvp(
    lambda primals, tangents: jax.jvp(plain_smallest, primals, tangents)
)


def smallest_right_vectors(jac: Float[Array, "B m n"]) -> Float[Array, "B n"]:
    """Right singular vectors of the smallest singular values of a stack of matrices
    (block inverse iteration on ``JᵀJ`` + Rayleigh–Ritz; module docstring). After the
    Gram matrices, one call of the compiled kernel where the kernels are in use
    (:func:`linkopt._engine.dense.smallest_right`): in XLA the steps were a few
    hundred small instructions per call (``benchmarks/bench_evaluation.py`` times
    the evaluation that calls it at every sample step)."""
    a = jnp.einsum("bmi,bmj->bij", jac, jac)
    n = a.shape[-1]
    start = np.random.default_rng(0).standard_normal((n, min(BLOCK, n)))
    start = jnp.broadcast_to(jnp.asarray(start), (a.shape[0],) + start.shape)
    if dense.serves_smallest_right(a, start.shape[-1]):
        return _kernel_smallest(a, start)
    return plain_smallest(a, start)


def sigmas_of(jac: Float[Array, "2 m n"]) -> Float[Array, 2]:
    """``(σ_min^FK, σ_min^BK)`` of the stacked Jacobians, differentiable in them."""
    v = smallest_right_vectors(jax.lax.stop_gradient(jac))
    image = jnp.einsum("bij,bj->bi", jac, v)
    return jnp.sqrt(jnp.sum(image**2, axis=1) + 1e-300)


def sigma_min_pair(mech: Mechanism, geom: Geometry, state) -> Float[Array, 2]:
    """``(σ_min^FK, σ_min^BK)`` at one state, differentiable in ``state`` and
    ``geom``: on the band (:mod:`linkopt._engine.banded_sigma`, cost linear in the
    bodies) wherever the FK/BK solves take it (:func:`linkopt._engine.banded.serves`),
    from the dense Jacobians otherwise."""
    from . import banded, banded_sigma  # local: banded_sigma imports this module

    if banded.serves(mech):
        return banded_sigma.sigma_min_pair(mech, geom, state)
    return sigmas_of(stacked_jacobians(mech, geom, state))


@jit
def f_sing_value(mech: Mechanism, geom: Geometry, state) -> Float[Array, ""]:
    """Eq. 3 at one state."""
    sigma = sigma_min_pair(mech, geom, state)
    return jnp.sum(1.0 / sigma)


@jit
def sigma_pairs(mech: Mechanism, state, design):
    geom = geometry(mech, design_vector(mech, design))
    state = jnp.asarray(state, dtype=jnp.float64)
    fn = lambda s: sigma_min_pair(mech, geom, s)  # noqa: E731
    return fn(state) if state.ndim == 1 else jax.vmap(fn)(state)


def singular_values(mech: Mechanism, state, *, design=None) -> Float[Array, "... 2"]:
    """``(σ_min^FK, σ_min^BK)`` of a homogenised state or a batch ``(N, S)`` of them;
    :class:`~linkopt.InputError` for any other shape (outside a trace). Non-finite
    states are allowed: maps pass unreached cells too, and get NaN for them."""
    if not isinstance(state, jax.core.Tracer):
        _check_shape(mech, state)
    if traced(mech, state, design):
        return sigma_pairs(mech, state, design)
    design = design_array(mech, design)  # None and arrays: one program

    def sigmas(s):  # the trace kept on disk (.programs)
        return programs.call("sigmas", mech, sigma_pairs, s, design)

    state = np.asarray(state, dtype=np.float64)
    return sigmas(state) if state.ndim == 1 else in_blocks(sigmas, (state,), one=sigmas)


def _check_shape(mech: Mechanism, state) -> None:
    size = mech.state_size
    try:
        shape = np.shape(state)
        numeric = np.asarray(state).dtype.kind in "iuf"
    except ValueError:  # ragged
        shape, numeric = None, False
    stacked = shape is not None and len(shape) == 2 and shape[0] >= 1
    if not numeric or not (shape == (size,) or (stacked and shape[1] == size)):
        raise InputError(
            f"state: expected a homogenised state ({size},) or (N, {size}) of "
            f"numbers, got {shape if numeric else type(state).__name__}"
        )


def f_sing(mech: Mechanism, state, *, design=None) -> Float[Array, ...]:
    """``f_sing`` (eq. 3) of a state or a batch of states."""
    return jnp.sum(1.0 / singular_values(mech, state, design=design), axis=-1)
