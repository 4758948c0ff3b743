"""Proximity to forward and backward singularities (paper eq. 3).

``f_sing(s) = 1/σ_min(∂C_FK/∂s) + 1/σ_min(∂C_BK/∂s)`` on the homogenised system. The
Jacobians are tall when a loop is planar but written in 3-D (redundant rows); σ_min is
then the smallest of the ``n`` column-rank singular values, ``n = |s|``.

The motor and output rows' Jacobians do not depend on the motor/output *targets*
(the wrapped difference has unit slope), so both Jacobians are functions of ``s`` only.

Hazard (jax 0.10, CPU): differentiating through ``jnp.linalg.svd`` under ``vmap``, or two
batched SVD calls in one jitted function, deadlocked inside LAPACK. So we take *one*
SVD of the stacked ``(2, m, n)`` Jacobians with the gradient stopped, and recover the
exact first derivative from ``σ = uᵀ J(s) v`` with the singular vectors held fixed
(valid for a simple smallest singular value). ``tests/test_singularity.py`` keeps a
regression test with a timeout.
"""

from __future__ import annotations

from functools import partial

import jax
import jax.numpy as jnp
from jaxtyping import Array, Float

from . import _jacobian
from ._geometry import Geometry, design_vector, geometry
from ._model import Mechanism


def stacked_jacobians(mech: Mechanism, geom: Geometry, state) -> Float[Array, "2 m n"]:
    """``[∂C_FK/∂s, ∂C_BK/∂s]`` at ``state`` (homogenised), from the closed-form
    block Jacobians of :mod:`linkopt._jacobian` (differentiable in state and design)."""
    return _jacobian.stacked_jacobians(mech, geom, state)


def sigma_min_pair(mech: Mechanism, geom: Geometry, state) -> Float[Array, "2"]:
    """``(σ_min^FK, σ_min^BK)`` at one state, differentiable in ``state`` and ``geom``."""
    jac = stacked_jacobians(mech, geom, state)
    u_all, _, vt_all = jnp.linalg.svd(jax.lax.stop_gradient(jac), full_matrices=False)
    k = min(jac.shape[1], jac.shape[2]) - 1
    u = u_all[:, :, k]
    v = vt_all[:, k, :]
    return jnp.einsum("bi,bij,bj->b", u, jac, v)


def f_sing_value(mech: Mechanism, geom: Geometry, state) -> Float[Array, ""]:
    """Eq. 3 at one state."""
    sigma = sigma_min_pair(mech, geom, state)
    return jnp.sum(1.0 / sigma)


@partial(jax.jit, static_argnums=0)
def _sigmas(mech: Mechanism, state, design):
    geom = geometry(mech, design_vector(mech, design))
    state = jnp.asarray(state, dtype=jnp.float64)
    fn = lambda s: sigma_min_pair(mech, geom, s)  # noqa: E731
    return fn(state) if state.ndim == 1 else jax.vmap(fn)(state)


def singular_values(mech: Mechanism, state, *, design=None) -> Float[Array, "... 2"]:
    """``(σ_min^FK, σ_min^BK)`` of a homogenised state or a batch ``(N, S)`` of them."""
    return _sigmas(mech, state, design)


def f_sing(mech: Mechanism, state, *, design=None) -> Float[Array, "..."]:
    """``f_sing`` (eq. 3) of a state or a batch of states."""
    return jnp.sum(1.0 / singular_values(mech, state, design=design), axis=-1)
