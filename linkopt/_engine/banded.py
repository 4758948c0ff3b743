"""Block-banded normal equations for mechanisms of many bodies: ``JᵀJ`` assembled in
band storage in an order of the bodies that keeps the band narrow, and factored by a
block Cholesky whose cost is linear in the bodies.

A constraint row touches at most two bodies, so ``JᵀJ`` is zero outside the
``7 x 7`` blocks ``(i, j)`` of bodies that share a row (a joint, a motor, an output of
one body relative to another). Numbered in the reverse Cuthill–McKee order of that
graph (:func:`linkopt._engine.body_order.body_order`), every such pair lies within
``w`` places of each other: a chain gives ``w = 1``, a ladder of closed loops a small
``w`` however long it is. The lower band is stored as ``band[i, k] = H[i, i - k]``,
shape ``(B, w + 1, 7, 7)``, in that order. Where a few hub bodies are joined to many
others (a walker's ground and crank) they go last and ``JᵀJ`` is an
:class:`linkopt._engine.arrowhead.Arrow` (the others' band, the hubs' border and
corner) instead.

* :func:`normal_equations`: ``(C, band, Jᵀ C)`` from the per-joint blocks of
  :mod:`linkopt._engine.jacobian`, scatter-added into the band (never a dense
  ``7B x 7B`` matrix).
* :func:`normal_solve`, :func:`motor_tangent` (``ds/da`` of a sample step) and
  :func:`adjoint_multiplier` (the partial gradient's ``μ``): the design evaluation's
  solves with ``JᵀJ`` on the band, taken where :func:`serves` says so
  (:mod:`linkopt._design.sampling`, :mod:`linkopt._design.partial`).
* :func:`factor`, :func:`cho_solve`, :func:`matvec`, :func:`trace`: on either storage
  (:mod:`linkopt._engine.band_factor`: ``O(B w² 7³)`` work, ``O(B w)`` memory;
  :mod:`linkopt._engine.arrowhead`: plus the Schur complement of the hubs).

:func:`predict`: the continuation's first-order prediction on the band and its chord
steps (:mod:`linkopt._engine.solvers.chord`), which reuse the prediction's rows and
factor.

:class:`Banded` is the :mod:`linkopt._engine.solvers.lm` method on this storage (with
geodesic acceleration from :data:`GEODESIC_BODIES` bodies on: :func:`geodesic`); the
FK/BK solves (:mod:`linkopt._engine.kinematics`) take it where :func:`serves` says so: a
mechanism of at least :data:`MIN_BODIES` bodies whose band is narrow
(:data:`MAX_WIDTH`), or one whose ``[solver]`` settings
ask for it (``factor = "banded"``, which tests set on small files). Below the
threshold the dense factor (:mod:`linkopt._engine.dense`, one kernel call) is faster
and keeps every earlier result bit for bit.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import partial

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from .._config import jit
from . import arrowhead, band_factor, dense
from .body_order import Layout, body_order
from .constraints import RESIDUALS, fk_residual, motor_residual
from .jacobian import row_groups
from .model import Mechanism
from .row_algebra import two_body_layout
from .solvers import chord as chord_steps

#: Fewest bodies for which the FK/BK solves take the banded factor by default. Timed
#: by ``benchmarks/bench_bodies.py`` on lazy tongs and ladders, the two break even
#: near 20 bodies (the dense factor is one fused kernel call up to 22 bodies, then
#: 3-4x slower at 24); every shipped mechanism but ``strandbeest_12.toml`` (74
#: bodies, the arrowhead) has at most 14 bodies and stays dense.
MIN_BODIES = 20
#: ... and whose band is at most this fraction of the bodies wide (without the hubs,
#: which the arrowhead order numbers last: :mod:`linkopt._engine.body_order`). A
#: band as wide as the mechanism is no better than the dense ``O(B³)`` and runs
#: slower than the dense kernel.
MAX_WIDTH = 1 / 8

Band = band_factor.Band


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


def _lower_values(pa: np.ndarray, pb: np.ndarray, prod):
    """The blocks ``H[max(pa, pb), min(pa, pb)]`` that ``prod[g] = H[pa[g], pb[g]]``
    and its transpose (the upper triangle's) add: ``prod`` or its transpose, their sum
    where ``pa == pb``."""
    lower = (pa >= pb)[:, None, None]
    flipped = jnp.swapaxes(prod, 1, 2)
    same = (pa == pb)[:, None, None]
    return jnp.where(same, prod + flipped, jnp.where(lower, prod, flipped))


def _add_block(band, layout: Layout, bodies_a, bodies_b, prod):
    """``band`` plus the blocks ``prod[g] = H[bodies_a[g], bodies_b[g]]`` (and their
    transposes, the upper triangle's, folded onto the lower band)."""
    pa, pb = layout.position[bodies_a], layout.position[bodies_b]
    values = _lower_values(pa, pb, prod)
    return band.at[np.maximum(pa, pb), np.abs(pa - pb)].add(values)


def _band_blocks(groups, layout: Layout, nb: int):
    """``(JᵀJ, Jᵀr)`` of ``groups`` in band storage."""
    band = jnp.zeros((nb, layout.width + 1, 7, 7))
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
    return band, grad


def _arrow_blocks(groups, layout: Layout, nb: int):
    """``(JᵀJ, Jᵀr)`` of ``groups`` in :class:`arrowhead.Arrow` storage."""
    arrow = arrowhead.zeros(nb - layout.hubs, layout.width, layout.hubs)
    grad = jnp.zeros((nb, 7))
    for group in groups:
        r = group.values
        for a, (bodies_a, jac_a) in enumerate(group.blocks):
            pa = layout.position[bodies_a]
            grad = grad.at[pa].add(jnp.einsum("gmi,gm->gi", jac_a, r))
            arrow = arrowhead.add(arrow, pa, pa, _gram(jac_a, jac_a))
            for bodies_b, jac_b in group.blocks[a + 1 :]:
                pb = layout.position[bodies_b]
                values = _lower_values(pa, pb, _gram(jac_a, jac_b))
                arrow = arrowhead.add(
                    arrow, np.maximum(pa, pb), np.minimum(pa, pb), values
                )
    return arrow, grad


def _kernel_blocks(groups, layout: Layout, nb: int):
    """:func:`_band_blocks` (or :func:`_arrow_blocks`, where the layout has hubs) in
    one call of the compiled ``band_normal`` (``arrow_normal``) handler: the rows two
    bodies wide (:func:`.row_algebra.two_body_layout`), their bodies' places in the
    layout as its attribute; its derivative that of the same sums in plain JAX
    (:func:`_row_blocks`). Measured on lazy tongs of 1000 bodies: the scatter adds
    took 3.1 of :func:`normal_equations`' 3.7 ms."""
    residual, rows, pairs = two_body_layout(groups)
    places = np.where(pairs >= 0, layout.position[np.maximum(pairs, 0)], -1)
    places = np.ascontiguousarray(places, dtype=np.int32).tobytes()
    return _kernel_normal(rows, residual, places, nb, layout.width + 1, layout.hubs)


def _storage_shapes(nb: int, w1: int, hubs: int) -> tuple:
    n = nb - hubs
    band = [(n, w1, 7, 7)]
    return tuple(band + [(n, hubs, 7, 7), (hubs, hubs, 7, 7)] if hubs else band)


@partial(jax.custom_jvp, nondiff_argnums=(2, 3, 4, 5))
def _kernel_normal(rows, residual, places: bytes, nb: int, w1: int, hubs: int):
    batch = rows.shape[:-2]
    shapes = _storage_shapes(nb, w1, hubs) + ((nb, 7),)
    results = tuple(jax.ShapeDtypeStruct((*batch, *s), rows.dtype) for s in shapes)
    pairs = np.frombuffer(places, dtype=np.int32)
    key = "arrow_normal" if hubs else "band_normal"
    *storage, grad = dense.call_kernel(key, results, rows, residual, pairs=pairs)
    return (arrowhead.Arrow(*storage) if hubs else storage[0]), grad


@_kernel_normal.defjvp
def _kernel_normal_jvp(places, nb, w1, hubs, primals, tangents):
    def plain(rows, residual):
        return _row_blocks(rows, residual, places, nb, w1, hubs)

    out = _kernel_normal(*primals, places, nb, w1, hubs)
    return out, jax.jvp(plain, primals, tangents)[1]


def _row_blocks(rows, residual, places: bytes, nb: int, w1: int, hubs: int):
    """``(JᵀJ, Jᵀr)`` in band (``hubs`` 0) or arrowhead storage of rows two bodies
    wide whose bodies are in the layout's places ``places`` (``(m, 2)`` int32 bytes,
    ``-1`` none), in plain JAX."""
    where = np.frombuffer(places, dtype=np.int32).reshape(-1, 2)
    if hubs:
        storage = arrowhead.zeros(nb - hubs, w1 - 1, hubs)
        add = arrowhead.add
    else:
        storage = jnp.zeros((nb, w1, 7, 7), dtype=rows.dtype)

        def add(band, row, col, values):
            return band.at[row, row - col].add(values)

    grad = jnp.zeros((nb, 7), dtype=rows.dtype)
    sides = (rows[:, :7], rows[:, 7:])
    for side, block in enumerate(sides):
        used = np.flatnonzero(where[:, side] >= 0)
        at = where[used, side]
        grad = grad.at[at].add(block[used] * residual[used, None])
        storage = add(storage, at, at, block[used, :, None] * block[used, None, :])
    both = np.flatnonzero(np.all(where >= 0, axis=1))
    pa, pb = where[both, 0], where[both, 1]
    prod = sides[0][both, :, None] * sides[1][both, None, :]
    values = _lower_values(pa, pb, prod)
    return add(storage, np.maximum(pa, pb), np.minimum(pa, pb), values), grad


def _assembled(groups, layout: Layout, nb: int):
    """``(JᵀJ, Jᵀr)`` of ``groups`` in the layout's storage (the arrowhead where it
    has hubs, else the band), assembled by the compiled kernel where it serves."""
    if groups and dense.kernels_serve(*[g.values for g in groups]):
        return _kernel_blocks(groups, layout, nb)
    if layout.hubs:
        return _arrow_blocks(groups, layout, nb)
    return _band_blocks(groups, layout, nb)


@partial(jit, static_argnums=2)
def normal_equations(mech: Mechanism, geom, kind: str, values, state):
    """``(C, band, g)``: the residual (row order of ``fk_residual``/``bk_residual``),
    ``JᵀJ`` in band storage ``(B, w + 1, 7, 7)`` and ``JᵀC`` ``(B, 7)``, both in the
    :class:`Layout`'s order (:func:`layout` gives it), assembled from ``7 x 7`` body
    blocks; equal to the dense :func:`linkopt._engine.jacobian.normal_equations` up
    to rounding."""
    passive, tail, order = row_groups(mech, geom, kind, values, state)
    groups = passive + tail
    layout = body_order(mech.num_bodies, _pairs(groups))
    band, grad = _assembled(groups, layout, mech.num_bodies)
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


def passive_normal(mech: Mechanism, geom, state) -> tuple:
    """``(JᵀJ, layout)``: ``JᵀJ`` of the passive rows alone
    (:func:`~.constraints.passive_residual`, motors as passive joints: the mobility
    test's matrix) in band or arrowhead storage, and the :class:`Layout` of its order
    (static)."""
    passive, _, _ = row_groups(mech, geom, "fk", jnp.zeros(mech.num_motors), state)
    where = body_order(mech.num_bodies, _pairs(passive))
    return _assembled(passive, where, mech.num_bodies)[0], where


def factor(band, damping):
    """The block Cholesky factor of ``band + damping I``: :func:`band_factor.factor`
    for a plain band, :func:`arrowhead.factor` for an :class:`arrowhead.Arrow`."""
    if isinstance(band, arrowhead.Arrow):
        return arrowhead.factor(band, damping)
    return band_factor.factor(band, damping)


def cho_solve(lower, b: Float[Array, "B 7"]) -> Float[Array, "B 7"]:
    """``x`` with ``L Lᵀ x = b`` for the factor of :func:`factor`."""
    if isinstance(lower, arrowhead.ArrowFactor):
        return arrowhead.cho_solve(lower, b)
    return band_factor.cho_solve(lower, b)


def matvec(band, x: Float[Array, "B 7"]) -> Float[Array, "B 7"]:
    """``H x`` for ``H`` in band (or arrowhead) storage."""
    if isinstance(band, arrowhead.Arrow):
        return arrowhead.matvec(band, x)
    return band_factor.matvec(band, x)


def trace(band) -> Float[Array, ""]:
    """The trace of ``H``."""
    if isinstance(band, arrowhead.Arrow):
        return arrowhead.trace(band)
    return jnp.sum(jnp.trace(band[:, 0], axis1=1, axis2=2))


def largest_block_trace(band) -> Float[Array, ""]:
    """``max_i tr(H_ii)`` over the diagonal ``7 x 7`` blocks (a body's)."""
    if isinstance(band, arrowhead.Arrow):
        hubs = jnp.trace(jnp.diagonal(band.corner, axis1=0, axis2=1), axis1=0, axis2=1)
        return jnp.maximum(largest_block_trace(band.band), jnp.max(hubs))
    return jnp.max(jnp.trace(band[:, 0], axis1=1, axis2=2))


def size(band) -> int:
    """The bodies ``B`` of ``H``."""
    if isinstance(band, arrowhead.Arrow):
        return band.band.shape[0] + band.corner.shape[0]
    return band.shape[0]


def permute(layout: Layout, state: Float[Array, " S"]) -> Float[Array, "B 7"]:
    """A state or state tangent in the band's order, one row per body."""
    return state.reshape(-1, 7)[layout.order]


def unpermute(layout: Layout, rows: Float[Array, "B 7"]) -> Float[Array, " S"]:
    return rows[layout.position].reshape(-1)


def damped_solve(band, damping, gradient: Float[Array, "B 7"]):
    """``(H + λI)⁻¹ g`` in the layout's order (band or arrowhead storage)."""
    return cho_solve(factor(band, damping), gradient)


#: Geodesic acceleration's largest bend (:class:`Banded`): the step is ``v + ½ a`` where
#: ``2 |a| <= ACCELERATION_RATIO |v|`` (Transtrum & Sethna's α), ``v`` elsewhere.
ACCELERATION_RATIO = 0.75
#: Fewest bodies whose FK/BK solves on the band take the geodesic acceleration and
#: the damping scaled with ``|C|²`` (:func:`geodesic`). From 100 bodies on, plain LM
#: fails the design evaluation of long soft linkages: measured on lazy tongs of 100
#: bodies (``benchmarks/bench_bodies.py``'s), its IK and adversarial samples crept
#: 0.008 rad from rest in 40 iterations each (at 300 and 1000 bodies every trial step
#: was refused), where with both they reach 0.64 rad, the evaluation 2.6x faster (3.27
#: -> 1.26 s, its first call 18.0 -> 18.7 s); FK from the first-order prediction of
#: a 0.2 rad turn took 9 iterations, 3 with both. Below it plain LM does as well (30
#: and 60 bodies: the same samples) and the acceleration's second derivative and
#: reverse pass would lengthen the compile of every smaller banded solve, the shipped
#: 74-body ``strandbeest_12.toml`` included, whose programs stay as they were.
GEODESIC_BODIES = 100


def geodesic(mech: Mechanism) -> bool:
    """Whether the FK/BK solves of ``mech`` on the band take :class:`Banded`'s
    geodesic acceleration and LM's damping scaled with ``|C|²``
    (:mod:`linkopt._engine.solvers.lm`'s ``residual_scaled``; the accelerated step
    is what lets the damping fall that fast: measured on lazy tongs of 1000 bodies,
    the plain step with it took 54 iterations where the accelerated one took 3): at
    least :data:`GEODESIC_BODIES` bodies."""
    return mech.num_bodies >= GEODESIC_BODIES


@dataclass(frozen=True)
class Banded:
    """The :class:`linkopt._engine.solvers.lm.NormalEquations` step on band storage
    for the solves of ``mech`` (``kind`` "fk"/"bk" at ``values``), with geodesic
    acceleration; ``model`` is ``(band, g)`` in the :class:`Layout`'s order.

    The step is ``δ = v + ½ a``: the damped Gauss–Newton velocity
    ``v = -(JᵀJ + λI)⁻¹ Jᵀr`` and the acceleration ``a = -(JᵀJ + λI)⁻¹ Jᵀ r_vv``,
    ``r_vv = D²C[v, v]`` the residual's second derivative along ``v`` (forward over
    forward mode) and ``Jᵀ r_vv`` by reverse mode, both solves on the one factor.
    Where the bend is large, ``2 |a| > ACCELERATION_RATIO |v|``, the step is ``v``
    alone; the predicted decrease is the velocity's (its linear model) either way.
    Transtrum & Sethna, "Improvements to the Levenberg-Marquardt algorithm for
    nonlinear least-squares minimization" (2012), Sec. 3, reject such a step and raise
    the damping instead; measured on ``strandbeest_12.toml`` (74 bodies, the
    arrowhead) from the first-order prediction of a 0.3 rad turn, that took 12
    iterations, the plain step 5 and this one 4 (and the same 16 on the tongs
    below).

    Why: long linkages are stiff along their length and soft across it (lazy tongs'
    smallest eigenvalue of ``JᵀJ`` at rest falls as the bodies to the fourth power:
    4.8e-6, 3.4e-8, 4.0e-10 and 3.2e-12 at 30, 100, 300 and 1000 bodies, the
    largest 24 throughout), and their constraint surface curves along the soft mode,
    so plain LM's damping stays near the trust region's edge (Nielsen's rule barely
    lowers it at ``ρ ≈ 0.6``) and the soft mode converges a percent or two per
    iteration. Measured on lazy tongs of 1000 bodies, one continuation step of 0.04
    rad from rest after its chord steps: 59 LM iterations to ``max |C| <= 1e-12``
    plainly, 16 with the acceleration, 3 with the acceleration and the damping the
    walk's corrector scales with ``|C|²`` (:func:`geodesic`), the answers 1.4e-8
    apart (the soft mode's freedom at the tolerance); smaller continuation steps did
    not help the plain solve (0.005 rad steps: 22-24 iterations each)."""

    mech: Mechanism
    geom: object
    kind: str
    values: object
    #: False: the plain damped step ``v`` (the comparison)
    geodesic: bool = True

    def linearise(self, x):
        residual, band, grad = normal_equations(
            self.mech, self.geom, self.kind, self.values, x
        )
        return residual, (band, grad)

    def _residual(self, x):
        return RESIDUALS[self.kind](self.mech, self.geom, self.values, x)

    def direction(self, x, model, residual, damping):
        band, grad = model
        where = layout(self.mech, self.geom, self.kind)
        lower = factor(band, damping)
        velocity = -cho_solve(lower, grad)
        predicted = -(
            2.0 * jnp.sum(velocity * grad) + jnp.sum(velocity * matvec(band, velocity))
        )
        moved = unpermute(where, velocity)
        if not self.geodesic:
            return moved, predicted
        curvature = jax.jvp(
            lambda y: jax.jvp(self._residual, (y,), (moved,))[1], (x,), (moved,)
        )[1]
        _, pull = jax.vjp(self._residual, x)
        bend = -cho_solve(lower, permute(where, pull(curvature)[0]))
        bounded = 2.0 * jnp.sqrt(jnp.sum(bend * bend)) <= (
            ACCELERATION_RATIO * jnp.sqrt(jnp.sum(velocity * velocity))
        )
        step = jnp.where(bounded, velocity + 0.5 * bend, velocity)
        return unpermute(where, step), predicted


def _gradient(groups, residuals, layout: Layout, nb: int) -> Float[Array, "B 7"]:
    """``Jᵀ r`` in the layout's order for the Jacobian blocks of ``groups`` and a
    residual ``residuals`` given group by group (each like its group's values)."""
    grad = jnp.zeros((nb, 7))
    for group, r in zip(groups, residuals, strict=True):
        for bodies, jac in group.blocks:
            grad = grad.at[layout.position[bodies]].add(
                jnp.einsum("gmi,gm->gi", jac, r)
            )
    return grad


#: The prediction's factor is of ``JᵀJ + PREDICTION_SHIFT · max_i tr(H_ii) · I``: a
#: shift at the factor's own rounding (the band Cholesky perturbs ``H`` by about
#: ``7(w + 1) · u · max H_ii``, u the unit round-off: 3e-14 for lazy tongs, whose
#: largest block trace is 37), so that the factor of a ``JᵀJ`` singular to
#: round-off stays finite, and no larger: the chord steps converge along an eigenvector
#: of ``JᵀJ`` at the rate ``shift / (eigenvalue + shift)`` at best, and a soft mode
#: under about three times the shift stops them. The dense path's fixed
#: :data:`linkopt._engine.continuation.PREDICTION_DAMPING` (1e-12) did that to lazy
#: tongs of 1000 bodies (smallest eigenvalue 3.2e-12): the chords stopped at ``max
#: |C|`` 1e-4 and 3 LM iterations followed; with this shift (3.7e-14) the chords close
#: every row (FK from rest, ``bench_bodies.py``'s rows, alternating with the fixed
#: shift: 38-48 -> 18-24 ms per solve). Soft modes under it (tongs of several thousand
#: bodies) are left to the LM corrector, as before.
PREDICTION_SHIFT = 1e-15


@partial(jit, static_argnums=(1, 5))
def predict(mech: Mechanism, kind: str, geom, values, state, chords: int = 0):
    """``(first, corrected)``: :func:`linkopt._engine.continuation.predict` on the band,
    and that prediction after at most ``chords`` chord steps
    (:func:`.solvers.chord.solve`) with the rows and the factor it was made with:
    ``p ← p - (JᵀJ)⁻¹ Jᵀ C(values, p)``, ``J`` the old state's, each step a residual
    at the new point (the values of :func:`row_groups` alone; the compiler drops their
    derivative blocks) and the factor's two scans, where a LM iteration assembles and
    factors the band anew.

    ``C(values, s + ṡ)`` is ``½ D²C[ṡ, ṡ]`` to third order in the step (``C`` is
    affine in the values, and the tangent cancels the first-order terms), so the
    first chord step lands on ``s + ṡ + ½ s̈``, the second-order prediction, and
    each further one removes another order of the step."""
    passive, tail, _ = row_groups(mech, geom, kind, values, state)
    groups = passive + tail
    where = body_order(mech.num_bodies, _pairs(groups))
    band, grad = _assembled(groups, where, mech.num_bodies)
    lower = factor(band, PREDICTION_SHIFT * largest_block_trace(band))
    first = state - unpermute(where, cho_solve(lower, grad))
    if not chords:
        return first, first

    def residual(p):
        passive, tail, _ = row_groups(mech, geom, kind, values, p)
        return [g.values for g in passive + tail]

    def step(r):
        grad = _gradient(groups, r, where, mech.num_bodies)
        return unpermute(where, cho_solve(lower, grad))

    return first, chord_steps.solve(
        residual, step, first, tolerance=mech.solver.tolerance, limit=chords
    )


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


def normal_solve(mech: Mechanism, kind: str, geom, state, rhs: Float[Array, "S k"]):
    """``(JᵀJ)⁻¹ rhs`` for the ``k`` columns of ``rhs`` (state coordinates), ``J``
    the Jacobian of ``kind`` at ``state``: one banded factor (no gradient through it)
    and its two scans per column; what :func:`linkopt._engine.dense.solve_spd` gives
    with the dense ``JᵀJ``."""
    count = mech.num_motors if kind == "fk" else mech.num_outputs
    _, band, _ = normal_equations(
        mech,
        jax.lax.stop_gradient(geom),
        kind,
        jnp.zeros(count),
        jax.lax.stop_gradient(state),
    )
    lower = factor(band, 0.0)
    where = layout(mech, geom, kind)

    def column(b):
        return unpermute(where, cho_solve(lower, permute(where, b)))

    return jax.vmap(column, in_axes=1, out_axes=1)(rhs)


def motor_rows_transposed(
    mech: Mechanism, geom, motors, state, columns: Float[Array, "M k"]
) -> Float[Array, "S k"]:
    """``Jᵀ c`` (``J = ∂C_FK/∂s``) for columns ``c`` that are zero outside the motor
    rows, given by their motor rows: reverse mode through the motor rows alone. The
    passive rows' share is exactly zero, so the product equals the one through the
    whole residual, without its reverse pass (most of the residual's operations)."""
    _, pull = jax.vjp(lambda s: motor_residual(mech, geom, motors, s), state)
    return jax.vmap(lambda c: pull(c)[0], in_axes=1, out_axes=1)(columns)


def motor_tangent(mech: Mechanism, geom, motors, state) -> Float[Array, "S M"]:
    """``ds/da = -(JᵀJ)⁻¹ Jᵀ ∂C_FK/∂a`` at a solved state on the band (the dense
    :func:`linkopt._design.sampling.state_motor_jacobian`): ``∂C_FK/∂a`` (nonzero in
    the motor rows only) by forward mode, ``Jᵀ`` by reverse mode through the motor
    rows (:func:`motor_rows_transposed`), never a dense ``J``."""
    jac_a = jax.jacfwd(lambda a: motor_residual(mech, geom, a, state))(motors)
    projected = motor_rows_transposed(mech, geom, motors, state, jac_a)
    return -normal_solve(mech, "fk", geom, state, projected)


def adjoint_multiplier(mech: Mechanism, geom, motors, state, d_state):
    """``μ = J (JᵀJ)⁻¹ ∂g/∂s`` of :func:`linkopt._design.partial.adjoint_term` with
    ``J = ∂C_FK/∂s`` on the band: one banded solve and a forward-mode product."""
    solved = normal_solve(mech, "fk", geom, state, d_state[:, None])[:, 0]
    _, mu = jax.jvp(lambda s: fk_residual(mech, geom, motors, s), (state,), (solved,))
    return mu
