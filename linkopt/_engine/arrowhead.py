"""Block-arrowhead storage of ``JᵀJ`` for a mechanism whose few *hub* bodies (a
walker's ground and crank) are joined to many others: the hubs numbered last
(:mod:`linkopt._engine.body_order`), ``H = [[A, Cᵀ], [C, D]]`` with ``A`` the
``n = B - h`` other bodies in block-band storage, ``C`` the ``h x n`` border and ``D``
the ``h x h`` corner.

* :class:`Arrow`: ``band`` ``(n, w + 1, 7, 7)`` (``A``, as
  :mod:`linkopt._engine.band_factor`), ``border`` ``(n, h, 7, 7)`` with
  ``border[i, j] = H[hub j, body i]``, ``corner`` ``(h, h, 7, 7)`` (both triangles).
* :func:`factor`: ``A + λI = L Lᵀ`` (the band's block Cholesky), ``Xᵀ = L⁻¹ Cᵀ`` (a
  forward scan with ``7h`` right-hand sides) and the Cholesky factor of the Schur
  complement ``D + λI - X Xᵀ``: ``O(n (w² + h w + h²) 7³ + h³ 7³)``, linear in the
  bodies for a fixed number of hubs.
* :func:`cho_solve`, :func:`matvec`, :func:`trace` on vectors ``(B, 7)`` in the
  layout's order (the hubs' rows last).
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from . import band_factor, dense


class Arrow(NamedTuple):
    """``JᵀJ`` with ``h`` hub bodies last (module docstring)."""

    band: Float[Array, "n w1 7 7"]
    border: Float[Array, "n h 7 7"]
    corner: Float[Array, "h h 7 7"]


class ArrowFactor(NamedTuple):
    """``lower`` the band's factor, ``cross`` ``Xᵀ = L⁻¹ Cᵀ`` ``(n, 7, 7h)``,
    ``corner`` the lower Cholesky factor of the Schur complement ``(7h, 7h)``."""

    lower: Float[Array, "n w1 7 7"]
    cross: Float[Array, "n 7 k"]
    corner: Float[Array, "k k"]


def zeros(rows: int, width: int, hubs: int) -> Arrow:
    return Arrow(
        jnp.zeros((rows, width + 1, 7, 7)),
        jnp.zeros((rows, hubs, 7, 7)),
        jnp.zeros((hubs, hubs, 7, 7)),
    )


def add(arrow: Arrow, row: np.ndarray, col: np.ndarray, values) -> Arrow:
    """``arrow`` plus the lower blocks ``values[g] = H[row[g], col[g]]``
    (``row >= col``, positions in the layout's order; a corner block off its diagonal
    also adds its transpose above)."""
    n = arrow.band.shape[0]
    in_band = np.nonzero(row < n)[0]
    in_border = np.nonzero((row >= n) & (col < n))[0]
    in_corner = np.nonzero(col >= n)[0]
    off = in_corner[row[in_corner] != col[in_corner]]
    band = arrow.band.at[row[in_band], row[in_band] - col[in_band]].add(values[in_band])
    border = arrow.border.at[col[in_border], row[in_border] - n].add(values[in_border])
    corner = arrow.corner.at[row[in_corner] - n, col[in_corner] - n].add(
        values[in_corner]
    )
    corner = corner.at[col[off] - n, row[off] - n].add(jnp.swapaxes(values[off], 1, 2))
    return Arrow(band, border, corner)


def _dense_corner(blocks: Float[Array, "h h 7 7"]) -> Float[Array, "k k"]:
    h = blocks.shape[0]
    return jnp.transpose(blocks, (0, 2, 1, 3)).reshape(7 * h, 7 * h)


def factor(arrow: Arrow, damping) -> ArrowFactor:
    """The factor of ``arrow + damping I`` (NaN from a non-positive pivot on)."""
    n, h = arrow.border.shape[:2]
    lower = band_factor.factor(arrow.band, damping)
    c_t = jnp.transpose(arrow.border, (0, 3, 1, 2)).reshape(n, 7, 7 * h)  # Cᵀ rows
    cross = jax.vmap(band_factor.forward, in_axes=(None, 2), out_axes=2)(lower, c_t)
    schur = _dense_corner(arrow.corner) + damping * jnp.eye(7 * h)
    schur = schur - jnp.einsum("nak,nal->kl", cross, cross)
    return ArrowFactor(lower, cross, dense.cholesky(schur))


def cho_solve(lower: ArrowFactor, b: Float[Array, "B 7"]) -> Float[Array, "B 7"]:
    """``x`` with ``H x = b`` for the factor of :func:`factor`."""
    n = lower.lower.shape[0]
    y = band_factor.forward(lower.lower, b[:n])
    rest = b[n:].reshape(-1) - jnp.einsum("nak,na->k", lower.cross, y)
    hub = dense.solve_lower_transpose(
        lower.corner, dense.solve_lower(lower.corner, rest)
    )
    x = band_factor.backward(lower.lower, y - jnp.einsum("nak,k->na", lower.cross, hub))
    return jnp.concatenate([x, hub.reshape(-1, 7)])


def matvec(arrow: Arrow, x: Float[Array, "B 7"]) -> Float[Array, "B 7"]:
    """``H x``."""
    n = arrow.band.shape[0]
    body, hub = x[:n], x[n:]
    top = band_factor.matvec(arrow.band, body)
    top = top + jnp.einsum("njba,jb->na", arrow.border, hub)
    bottom = jnp.einsum("njab,nb->ja", arrow.border, body)
    bottom = bottom + jnp.einsum("jkab,kb->ja", arrow.corner, hub)
    return jnp.concatenate([top, bottom])


def trace(arrow: Arrow) -> Float[Array, ""]:
    diagonal = jnp.trace(arrow.band[:, 0], axis1=1, axis2=2)
    hubs = jnp.trace(jnp.diagonal(arrow.corner, axis1=0, axis2=1), axis1=0, axis2=1)
    return jnp.sum(diagonal) + jnp.sum(hubs)
