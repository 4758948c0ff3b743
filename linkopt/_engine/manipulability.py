"""Yoshikawa's manipulability of any Mechanism, from the engine's motor sensitivities.

Paper 004, eq. 1: ``w = sqrt(det(J Jᵀ))`` with ``J`` the velocity Jacobian of the end
effector with respect to the joint (motor) variables; for a square ``J`` it reduces to
``|det J|`` (eq. 2). Here ``J = ∂p/∂s · ds/da`` (``k × M``): ``ds/da`` is the implicit
sensitivity of the solved state to the motors (:func:`linkopt.sensitivity`, eq. 2 of
paper 001), so closed loops (e.g. the five-bar, whose passive joints move with the
motors) are handled exactly like serial arms. ``p`` is a named point and ``k`` the
Cartesian coordinates of it that count (default: those the mechanism declares as
outputs of that point; x, y for the planar five-bar).

``w`` is the product of the ``min(k, M)`` singular values of ``J``, i.e. proportional
to the volume of the manipulability ellipsoid. When ``k > M`` (fewer motors than task
coordinates) ``det(J Jᵀ)`` vanishes identically; we then use ``sqrt(det(Jᵀ J))``, the
same singular-value product — a choice the paper does not need (its arms are square or
redundant) and which we state here. Units: file units per rad (revolute motors) or
dimensionless (linear motors), as the paper's "ellipsoid volume".
"""

from __future__ import annotations

from functools import partial

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from .._config import jit
from .._errors import InputError
from . import dense_lu
from .kinematics import sensitivity
from .model import Mechanism
from .readout import point_positions


def yoshikawa(jac: Float[Array, "k M"]) -> Float[Array, ""]:
    """``sqrt(det(J Jᵀ))`` for ``k ≤ M``, else ``sqrt(det(Jᵀ J))`` (eq. 1); 0 at a
    singularity."""
    k, m = jac.shape
    gram = jac @ jac.T if k <= m else jac.T @ jac
    det = dense_lu.det(gram)  # no LAPACK call (linkopt._config)
    positive = det > 0.0
    return jnp.where(positive, jnp.sqrt(jnp.where(positive, det, 1.0)), 0.0)


def _select(
    mech: Mechanism, point: str | None, coordinates
) -> tuple[int, tuple[int, ...]]:
    """Static (point index, coordinate indices); defaults from the mechanism's
    outputs."""
    if not mech.point_names:
        raise InputError(
            f"{mech.source}: [[points]]: manipulability needs a named end-effector "
            "point; the mechanism has none"
        )
    if point is None:
        positional = [int(p) for p in mech.output_points if p >= 0]
        index = positional[0] if positional else 0
    elif point in mech.point_names:
        index = mech.point_names.index(point)
    else:
        raise InputError(
            f"{mech.source}: [[points]]: no point named {point!r}; expected one of "
            f"{list(mech.point_names)}"
        )
    if coordinates is None:
        declared = sorted(
            {
                int(c)
                for p, c in zip(mech.output_points, mech.output_coords)
                if p == index
            }
        )
        return index, tuple(declared) if declared else (0, 1, 2)
    coords = tuple(
        "xyz".index(c) if isinstance(c, str) and c in "xyz" else c for c in coordinates
    )
    if (
        not coords
        or any(c not in (0, 1, 2) for c in coords)
        or len(set(coords)) != len(coords)
    ):
        raise InputError(
            "manipulability: coordinates: expected distinct entries of x, y, z, got "
            f"{coordinates!r}"
        )
    return index, coords


def _point_jacobian(
    mech: Mechanism, index: int, coords: tuple[int, ...], state, design
) -> Float[Array, "k M"]:
    ds_da = sensitivity(mech, state, "motors", design=design)
    dp_ds = jax.jacfwd(lambda s: point_positions(mech, s, design=design)[index])(state)
    return (dp_ds @ ds_da)[np.array(coords)]


@partial(jit, static_argnums=(1, 2))
def _batched(mech: Mechanism, index: int, coords: tuple[int, ...], states, design):
    jacs = jax.vmap(lambda s: _point_jacobian(mech, index, coords, s, design))(states)
    return jacs, jax.vmap(yoshikawa)(jacs)


def point_jacobian(
    mech: Mechanism, state, point: str | None = None, coordinates=None, *, design=None
) -> Float[Array, "... k M"]:
    """``∂p/∂a`` of a named point (file units per motor unit) at solved state(s)
    ``(..., S)``."""
    return _evaluate(mech, state, point, coordinates, design)[0]


def manipulability(
    mech: Mechanism, state, point: str | None = None, coordinates=None, *, design=None
) -> Float[Array, ...]:
    """Yoshikawa's ``w`` (eq. 1) of ``point`` at solved homogenised state(s)
    ``(..., S)``.

    ``point`` defaults to the point of the mechanism's first Cartesian output and
    ``coordinates`` (e.g. ``("x", "y")``) to that point's output coordinates.
    """
    return _evaluate(mech, state, point, coordinates, design)[1]


def _evaluate(mech, state, point, coordinates, design):
    from .geometry import design_vector

    index, coords = _select(mech, point, coordinates)
    state = jnp.asarray(state, dtype=jnp.float64)
    batch = state.shape[:-1]
    jacs, w = _batched(
        mech,
        index,
        coords,
        state.reshape(-1, state.shape[-1]),
        design_vector(mech, design),
    )
    return jacs.reshape(*batch, *jacs.shape[1:]), w.reshape(batch)
