"""σ_min of the FK and BK Jacobians of a mechanism of many bodies on the band
(:mod:`linkopt._engine.banded`): the same block inverse iteration and Rayleigh–Ritz
step as :mod:`linkopt._engine.singularity` (``BLOCK`` vectors, ``ITERATIONS`` sweeps,
the factor of ``JᵀJ`` shifted (:data:`SHIFT_BODIES`), a seeded start block), but
``(JᵀJ)⁻¹`` applied by the banded factor's two scans and ``JᵀJ`` never formed
densely, so one σ_min costs ``O(B w²)`` instead of the dense Gram matrix's ``O(B³)``
(and ``O(B w)`` memory instead of ``2 x 7B x 7B`` numbers).

The value is ``‖J v‖`` with the Ritz vector ``v`` held fixed, as there: an upper bound
on σ_min equal to it at convergence, whose derivative in the state and the geometry is
σ_min's for a simple smallest singular value. ``J v`` is a forward-mode product through
the residual (the motor/output targets play no part in ``J``).

:func:`linkopt._engine.singularity.sigma_min_pair` calls :func:`sigma_min_pair`
wherever the solves take the band (:func:`linkopt._engine.banded.serves`), so the
evaluation's σ_min at every sample step, the partial gradient's and the verification
grid's are these.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from . import banded, eigh
from .constraints import bk_residual, fk_residual
from .model import Mechanism
from .singularity import BLOCK, ITERATIONS, SHIFT

#: σ_min's factor is of ``JᵀJ + SHIFT·SHIFT_BODIES·max_i tr(H_ii)·I``: the dense
#: path's ``SHIFT·trace`` of a mechanism of 7 bodies as heavy as the heaviest one, not
#: growing with the bodies as the trace does. With ``SHIFT·trace`` a 3000-body ladder's
#: shift was 2600 times its σ_min² at rest (whose squares fall as ``1/B²``) and the
#: six sweeps overestimated σ_min 4x (8.7e-6 for 2.1e-6); at 1000 bodies both agree to
#: 8 digits.
SHIFT_BODIES = 7


def _orthonormalise(x: Float[Array, "B 7 k"]) -> Float[Array, "B 7 k"]:
    """Gram–Schmidt on the ``k`` columns, each projection twice."""
    columns = []
    for j in range(x.shape[-1]):
        v = x[..., j]
        for _ in range(2):
            for q in columns:
                v = v - jnp.sum(q * v) * q
        columns.append(v / jnp.sqrt(jnp.sum(v**2) + 1e-300))
    return jnp.stack(columns, axis=-1)


def start_block(bodies: int, k: int) -> np.ndarray:
    """The seeded start block ``(B, 7, k)`` of the inverse iteration."""
    start = np.random.default_rng(0).standard_normal((7 * bodies, k))
    return start.reshape(bodies, 7, k)


def smallest_subspace(band, start: Float[Array, "B 7 k"], iterations: int, shift=None):
    """Block inverse iteration on ``H = JᵀJ`` (band or arrowhead storage; the factor
    of ``H + shift·I``, by default :data:`SHIFT_BODIES` ``· SHIFT · max_i tr(H_ii)``),
    ``iterations`` sweeps
    from ``start``: an orthonormal block ``(B, 7, k)`` (the layout's order) that holds
    the right singular vectors of ``J``'s ``k`` smallest singular values once
    converged."""
    if shift is None:
        shift = SHIFT * SHIFT_BODIES * banded.largest_block_trace(band)
    lower = banded.factor(band, shift)
    solve = jax.vmap(lambda b: banded.cho_solve(lower, b), in_axes=2, out_axes=2)
    return jax.lax.fori_loop(
        0, iterations, lambda _, x: _orthonormalise(solve(x)), _orthonormalise(start)
    )


def smallest_right_vector(band) -> Float[Array, "B 7"]:
    """The right singular vector of the smallest singular value of ``J`` from
    ``JᵀJ`` in band (or arrowhead) storage (in the layout's order): the Ritz vector
    of :func:`smallest_subspace`'s ``BLOCK`` columns."""
    nb = banded.size(band)
    x = smallest_subspace(band, start_block(nb, min(BLOCK, 7 * nb)), ITERATIONS)
    image = jax.vmap(lambda v: banded.matvec(band, v), in_axes=2, out_axes=2)(x)
    _, ritz = eigh.symmetric_eigh(jnp.einsum("bai,baj->ij", x, image))
    return jnp.einsum("bak,k->ba", x, ritz[:, 0])


def largest_eigenvalue(band, iterations: int = 60) -> Float[Array, ""]:
    """``λ_max(H)`` by power iteration from a seeded start (a Rayleigh quotient:
    a lower bound, within a few per cent after ``iterations`` products)."""
    start = start_block(banded.size(band), 1)[..., 0]

    def sweep(_, x):
        y = banded.matvec(band, x)
        return y / jnp.sqrt(jnp.sum(y**2))

    x = jax.lax.fori_loop(0, iterations, sweep, start / np.linalg.norm(start))
    return jnp.sum(x * banded.matvec(band, x))


def sigma_min(mech: Mechanism, geom, kind: str, state) -> Float[Array, ""]:
    """σ_min of ``∂C_FK/∂s`` (``kind`` "fk") or ``∂C_BK/∂s`` ("bk") at ``state``,
    differentiable in ``state`` and ``geom``."""
    count = mech.num_motors if kind == "fk" else mech.num_outputs
    targets = jnp.zeros(count)
    _, band, _ = banded.normal_equations(
        mech, jax.lax.stop_gradient(geom), kind, targets, jax.lax.stop_gradient(state)
    )
    where = banded.layout(mech, geom, kind)
    v = jax.lax.stop_gradient(banded.unpermute(where, smallest_right_vector(band)))
    residual = fk_residual if kind == "fk" else bk_residual
    _, image = jax.jvp(lambda s: residual(mech, geom, targets, s), (state,), (v,))
    return jnp.sqrt(jnp.sum(image**2) + 1e-300)


def sigma_min_pair(mech: Mechanism, geom, state) -> Float[Array, 2]:
    """``(σ_min^FK, σ_min^BK)``, as :func:`linkopt._engine.singularity.sigma_min_pair`
    on the band."""
    return jnp.stack([sigma_min(mech, geom, kind, state) for kind in ("fk", "bk")])
