"""Block-banded normal equations for mechanisms of many bodies: ``JᵀJ`` assembled in
band storage in an order of the bodies that keeps the band narrow, and factored by a
block Cholesky whose cost is linear in the bodies.

A constraint row touches at most two bodies, so ``JᵀJ`` is zero outside the
``7 x 7`` blocks ``(i, j)`` of bodies that share a row (a joint, a motor, an output of
one body relative to another). Numbered in the reverse Cuthill–McKee order of that
graph (:func:`body_order`, ``scipy.sparse.csgraph``), every such pair lies within
``w`` places of each other: a chain gives ``w = 1``, a ladder of closed loops a small
``w`` however long it is. The lower band is stored as ``band[i, k] = H[i, i - k]``,
shape ``(B, w + 1, 7, 7)``, in that order.

* :func:`normal_equations`: ``(C, band, Jᵀ C)`` from the per-joint blocks of
  :mod:`linkopt._engine.jacobian`, scatter-added into the band (never a dense
  ``7B x 7B`` matrix).
* :func:`factor`: ``L`` with ``H + λI = L Lᵀ``, one ``lax.scan`` step per block row:
  row ``i`` of ``L`` is ``A[i, window] W⁻ᵀ`` with ``W`` the ``7w x 7w`` triangle of
  the ``w`` rows before it (the scan's carry), then the Cholesky factor of
  ``A[i, i] - L[i, window] L[i, window]ᵀ``; ``O(B w² 7³)`` work, ``O(B w)`` memory.
* :func:`cho_solve` (two scans), :func:`matvec`.

:class:`Banded` is the :mod:`linkopt._engine.lm` method on this storage; the FK/BK
solves (:mod:`linkopt._engine.kinematics`) take it where :func:`serves` says so: a
mechanism of at least :data:`MIN_BODIES` bodies whose band is narrow
(:data:`MAX_WIDTH`), or one whose ``[solver]`` settings
ask for it (``factor = "banded"``, which tests set on small files). Below the
threshold the dense factor (:mod:`linkopt._engine.dense`, one kernel call) is faster
and keeps every earlier result bit for bit.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from functools import partial

import jax
import jax.numpy as jnp
import numpy as np
import scipy.sparse
from jaxtyping import Array, Float
from scipy.sparse.csgraph import breadth_first_order, reverse_cuthill_mckee

from .._config import jit
from . import dense
from .jacobian import row_groups
from .model import Mechanism

#: Fewest bodies for which the FK/BK solves take the banded factor by default. Timed
#: by ``benchmarks/bench_bodies.py`` on lazy tongs and ladders, the two break even
#: near 20 bodies (the dense factor is one fused kernel call up to 22 bodies, then
#: 3-4x slower at 24); every shipped mechanism (at most 14 bodies) stays dense.
MIN_BODIES = 20
#: ... and whose band is at most this fraction of the bodies wide. A body joined to
#: many others (a ground or a crank that every leg of a walker hangs from) widens the
#: band to the whole mechanism, where the band's ``O(B w²)`` is no better than the
#: dense ``O(B³)`` and runs slower than the dense kernel.
MAX_WIDTH = 1 / 8

Band = Float[Array, "B w1 7 7"]


def serves(mech: Mechanism) -> bool:
    """Whether the FK/BK solves of ``mech`` use the banded factor: ``[solver]
    factor`` "banded", or "auto" with at least :data:`MIN_BODIES` bodies in a band at
    most :data:`MAX_WIDTH` of them wide."""
    factor = mech.solver.factor
    if factor != "auto":
        return factor == "banded"
    if mech.num_bodies < MIN_BODIES:
        return False
    pairs = np.concatenate([mech.joint_bodies, mech.output_table.bodies])
    pairs = pairs[np.all(pairs >= 0, axis=1)]
    return body_order(mech.num_bodies, pairs).width <= MAX_WIDTH * mech.num_bodies


@dataclass(frozen=True)
class Layout:
    """Where each body sits in the band: ``position[b]`` its block row, ``order`` the
    inverse (``order[position[b]] = b``), ``width`` the band's ``w`` (at least 1)."""

    order: np.ndarray
    position: np.ndarray
    width: int


def _peripheral_order(graph, num_bodies: int) -> np.ndarray:
    """Breadth-first order from a pseudo-peripheral body of each component (two
    sweeps: the last body reached from the first, then from that one), reversed:
    Cuthill–McKee's level structure from a far end."""
    seen = np.zeros(num_bodies, dtype=bool)
    parts = []
    for root in range(num_bodies):
        if seen[root]:
            continue
        far = breadth_first_order(graph, root, directed=False)[0][-1]
        far = breadth_first_order(graph, far, directed=False)[0][-1]
        order = breadth_first_order(graph, far, directed=False)[0]
        seen[order] = True
        parts.append(order)
    return np.concatenate(parts)[::-1]


def _width(edges: np.ndarray, order: np.ndarray) -> int:
    position = np.empty(order.size, dtype=np.int64)
    position[order] = np.arange(order.size)
    spread = np.abs(position[edges[:, 0]] - position[edges[:, 1]])
    return int(np.max(spread, initial=0))


@functools.lru_cache(maxsize=64)
def _layout(num_bodies: int, pairs: bytes) -> Layout:
    """The narrowest band of three orders: the file's, scipy's reverse Cuthill–McKee
    (which starts from a body of least degree, in the middle of a long ladder) and
    reverse Cuthill–McKee levels from a pseudo-peripheral body."""
    edges = np.frombuffer(pairs, dtype=np.int64).reshape(-1, 2)
    edges = edges[edges[:, 0] != edges[:, 1]]
    graph = scipy.sparse.coo_matrix(
        (np.ones(len(edges)), (edges[:, 0], edges[:, 1])), (num_bodies,) * 2
    ).tocsr()
    graph = graph + graph.T
    candidates = [
        np.arange(num_bodies),
        np.asarray(reverse_cuthill_mckee(graph, symmetric_mode=True)),
        _peripheral_order(graph, num_bodies),
    ]
    order = min(candidates, key=lambda o: _width(edges, o))
    position = np.empty(num_bodies, dtype=np.int64)
    position[order] = np.arange(num_bodies)
    return Layout(order, position, max(_width(edges, order), 1))


def body_order(num_bodies: int, pairs: np.ndarray) -> Layout:
    """The reverse Cuthill–McKee :class:`Layout` of bodies coupled by ``pairs``
    ``(E, 2)`` (body indices; isolated bodies keep a place of their own)."""
    pairs = np.ascontiguousarray(np.asarray(pairs, dtype=np.int64).reshape(-1, 2))
    return _layout(num_bodies, pairs.tobytes())


def _pairs(groups) -> np.ndarray:
    """Every pair of bodies that one row of ``groups`` touches."""
    found = [np.zeros((0, 2), dtype=np.int64)]
    for group in groups:
        for a, (bodies_a, _) in enumerate(group.blocks):
            for bodies_b, _ in group.blocks[a + 1 :]:
                found.append(np.stack([bodies_a, bodies_b], axis=1))
    return np.concatenate(found).astype(np.int64)


def _gram(a, b):
    """``Σ_m a[:, m]ᵀ b[:, m]`` for blocks ``(G, m, 7)``: ``(G, 7, 7)``."""
    return jnp.einsum("gmi,gmj->gij", a, b)


def _add_block(band, layout: Layout, bodies_a, bodies_b, prod):
    """``band`` plus the blocks ``prod[g] = H[bodies_a[g], bodies_b[g]]`` (and their
    transposes, the upper triangle's, folded onto the lower band)."""
    pa, pb = layout.position[bodies_a], layout.position[bodies_b]
    lower = (pa >= pb)[:, None, None]
    flipped = jnp.swapaxes(prod, 1, 2)
    same = (pa == pb)[:, None, None]
    values = jnp.where(same, prod + flipped, jnp.where(lower, prod, flipped))
    return band.at[np.maximum(pa, pb), np.abs(pa - pb)].add(values)


@partial(jit, static_argnums=(0, 2))
def normal_equations(mech: Mechanism, geom, kind: str, values, state):
    """``(C, band, g)``: the residual (row order of ``fk_residual``/``bk_residual``),
    ``JᵀJ`` in band storage ``(B, w + 1, 7, 7)`` and ``JᵀC`` ``(B, 7)``, both in the
    :class:`Layout`'s order (:func:`layout` gives it), assembled from ``7 x 7`` body
    blocks; equal to the dense :func:`linkopt._engine.jacobian.normal_equations` up
    to rounding."""
    passive, tail, order = row_groups(mech, geom, kind, values, state)
    groups = passive + tail
    layout = body_order(mech.num_bodies, _pairs(groups))
    nb, w = mech.num_bodies, layout.width
    band = jnp.zeros((nb, w + 1, 7, 7))
    grad = jnp.zeros((nb, 7))
    for group in groups:
        r = group.values
        for a, (bodies_a, jac_a) in enumerate(group.blocks):
            ga = jnp.einsum("gmi,gm->gi", jac_a, r)  # (G, 7)
            grad = grad.at[layout.position[bodies_a]].add(ga)
            same = np.zeros(len(bodies_a), dtype=int)
            band = band.at[layout.position[bodies_a], same].add(_gram(jac_a, jac_a))
            for bodies_b, jac_b in group.blocks[a + 1 :]:
                band = _add_block(band, layout, bodies_a, bodies_b, _gram(jac_a, jac_b))
    residual = jnp.concatenate([g.values.reshape(-1) for g in groups])
    if order:
        head = sum(int(np.prod(g.values.shape)) for g in passive)
        perm = np.argsort(np.concatenate(order), kind="stable")
        residual = residual[np.concatenate([np.arange(head), head + perm])]
    return residual, band, grad


def layout(mech: Mechanism, geom, kind: str) -> Layout:
    """The :class:`Layout` that :func:`normal_equations` uses for ``kind`` (static:
    only the structure decides it)."""
    passive, tail, _ = row_groups(mech, geom, kind, None, jnp.zeros(mech.state_size))
    return body_order(mech.num_bodies, _pairs(passive + tail))


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


def cho_solve(lower: Band, b: Float[Array, "B 7"]) -> Float[Array, "B 7"]:
    """``x`` with ``L Lᵀ x = b`` for the factor of :func:`factor`."""
    w = lower.shape[1] - 1

    def forward(previous, item):  # previous: y of rows i-w .. i-1
        blocks, rhs = item
        rhs = rhs - jnp.einsum("kab,kb->a", blocks[1:], previous[::-1])
        y = dense.solve_lower(blocks[0], rhs)
        return jnp.concatenate([previous[1:], y[None]]), y

    _, y = jax.lax.scan(forward, jnp.zeros((w, 7), dtype=b.dtype), (lower, b))

    def backward(pending, item):  # pending[m]: what rows i-m owe to later rows
        blocks, rhs = item
        x = dense.solve_lower_transpose(blocks[0], rhs - pending[0])
        owed = jnp.einsum("kba,b->ka", blocks[1:], x)  # rows i-1 .. i-w
        shifted = jnp.concatenate([pending[1:], jnp.zeros((1, 7), dtype=b.dtype)])
        return shifted + owed, x

    _, x = jax.lax.scan(
        backward, jnp.zeros((w, 7), dtype=b.dtype), (lower, y), reverse=True
    )
    return x


def matvec(band: Band, x: Float[Array, "B 7"]) -> Float[Array, "B 7"]:
    """``H x`` for ``H`` in band storage (the lower band and its transpose)."""
    nb, w = band.shape[0], band.shape[1] - 1
    rows = np.arange(nb)[:, None] - np.arange(w + 1)[None, :]  # (B, w+1): i - k
    valid = jnp.asarray(rows >= 0)[..., None]
    padded = jnp.where(valid, x[np.maximum(rows, 0)], 0.0)  # x[i - k]
    out = jnp.einsum("ikab,ikb->ia", band, padded)
    upper = jnp.einsum("ikba,ib->ika", band[:, 1:], x)  # to row i - k, k >= 1
    return out.at[np.maximum(rows[:, 1:], 0)].add(jnp.where(valid[:, 1:], upper, 0.0))


def permute(layout: Layout, state: Float[Array, " S"]) -> Float[Array, "B 7"]:
    """A state or state tangent in the band's order, one row per body."""
    return state.reshape(-1, 7)[layout.order]


def unpermute(layout: Layout, rows: Float[Array, "B 7"]) -> Float[Array, " S"]:
    return rows[layout.position].reshape(-1)


def damped_solve(band: Band, damping, gradient: Float[Array, "B 7"]):
    """``(H + λI)⁻¹ g`` in the band's order."""
    return cho_solve(factor(band, damping), gradient)


@dataclass(frozen=True)
class Banded:
    """The :class:`linkopt._engine.lm.NormalEquations` step on band storage:
    ``δ = -(JᵀJ + λI)⁻¹ Jᵀr`` for the solves of ``mech`` (``kind`` "fk"/"bk" at
    ``values``); ``model`` is ``(band, g)`` in the :class:`Layout`'s order."""

    mech: Mechanism
    geom: object
    kind: str
    values: object

    def linearise(self, x):
        residual, band, grad = normal_equations(
            self.mech, self.geom, self.kind, self.values, x
        )
        return residual, (band, grad)

    def direction(self, model, residual, damping):
        band, grad = model
        step = -damped_solve(band, damping, grad)
        predicted = -(2.0 * jnp.sum(step * grad) + jnp.sum(step * matvec(band, step)))
        where = layout(self.mech, self.geom, self.kind)
        return unpermute(where, step), predicted


def predict(mech: Mechanism, kind: str, geom, values, state):
    """:func:`linkopt._engine.kinematics.predict` on the band."""
    _, band, grad = normal_equations(mech, geom, kind, values, state)
    where = layout(mech, geom, kind)
    return state - unpermute(where, damped_solve(band, 1e-12, grad))


def tangent(mech: Mechanism, kind: str, geom, values, state, residual, rhs):
    """``-(JᵀJ)⁻¹ Jᵀ rhs`` (the implicit-function tangent of
    :func:`linkopt._engine.kinematics.implicit_state`), ``Jᵀ rhs`` by reverse mode
    through ``residual`` and the solve a ``custom_linear_solve`` on the band (so it
    transposes for reverse-mode derivatives)."""
    _, pull = jax.vjp(lambda s: residual(mech, geom, values, s), state)
    (projected,) = pull(rhs)
    _, band, _ = normal_equations(mech, geom, kind, values, state)
    band = jax.lax.stop_gradient(band)
    lower = factor(band, 0.0)
    where = layout(mech, geom, kind)
    solved = jax.lax.custom_linear_solve(
        lambda v: matvec(band, v),
        permute(where, projected),
        solve=lambda _, b: cho_solve(lower, b),
        symmetric=True,
    )
    return -unpermute(where, solved)
