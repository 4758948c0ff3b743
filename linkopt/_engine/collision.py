"""Clearance between link solids: exact capsule distances and a smooth barrier.

Each body's solid is a set of capsules (:mod:`.links`, the capsules the exporters
draw). A capsule's segment ends are places on its body (joint anchors and named points
at the rest pose of the design, plus the body's layer offset), written in the body's
frame, so they follow the body in any state: ``x_b + R(q_b) (place - origin_b)``, as
named points do (:func:`.constraints.homogenised_point_positions`).

* :func:`segment_distance` is the exact distance between two segments, and the
  clearance of two capsules is that distance minus their radii (negative when they
  overlap). Its gradient is Danskin's: the closest parameters ``(s*, t*)`` are held
  fixed (``stop_gradient``) and the distance between ``P(s*)`` and ``Q(t*)`` is
  differentiated, which is the derivative of the minimum wherever the closest pair is
  unique; parallel and zero-length segments (whose closest pair is not unique) give
  a finite gradient too, and crossing segments (distance 0, or below
  :data:`CROSSING` after rounding) a zero one: in the plane of two crossing links
  the distance stays 0 as they move, so the term's gradient there is zero, and only
  the pairs in the band short of crossing pull on the design.
* :func:`barrier` of a clearance ``g`` with the band ``c`` (``[collision].clearance``)
  is ``(max(0, c - g) / c)²``: zero when the capsules are clear by more than the band,
  1 at contact, 4 at an overlap of ``c``; C¹ at the band's edge (value and slope zero
  there), defined and growing through contact.
* :func:`collision_value` sums it over every capsule pair of every checked body pair.
  A sum, not a log-sum-exp: it is exactly zero when every pair is clear of the band
  (a log-sum-exp never is), C¹ as its terms are, and each pair in the band pulls on
  the design with its own gradient; the worst pair is reported separately.

Lengths inside are homogenised (divided by the reference length); :func:`clearance`
returns file units.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import partial

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float, Int

from .._config import jit
from .._errors import InputError
from . import programs
from .blocks import in_blocks
from .constraints import body_frames
from .geometry import Geometry, design_array, design_vector, geometry
from .model import Mechanism
from .rotations import rotate

#: Squared lengths below this (homogenised²) count as a zero-length segment.
TINY = 1e-30
#: Squared distances below this (homogenised²: 1e-12 reference lengths) count as
#: zero, crossing segments: rounding leaves two crossing segments ~1e-17 apart, and the
#: gradient of so small a distance is a unit vector in an arbitrary direction (the
#: distance has a cone's kink at 0), which would pull a design or a state at random.
CROSSING = 1e-24


def _safe_divide(num, den):
    """``num / den`` where ``den`` is not tiny, else 0 (no NaN, also in gradients)."""
    ok = jnp.abs(den) > TINY
    return jnp.where(ok, num / jnp.where(ok, den, 1.0), 0.0)


def _clip(x):
    """``x`` clamped to ``[0, 1]``, a segment's parameter range."""
    return jnp.clip(x, 0.0, 1.0)


def _candidates(p1, q1, p2, q2) -> Float[Array, "5 2"]:
    """Parameter pairs ``(s, t)`` among which the closest pair of the segments
    ``p1 + s (q1 - p1)``, ``p2 + t (q2 - p2)`` lies: the best ``t`` at ``s = 0, 1``,
    the best ``s`` at ``t = 0, 1`` (the four edges of the square ``[0, 1]²``, each a
    clamped 1-D minimisation), and the interior stationary point when the segments
    are not parallel. The minimum of a convex quadratic over the square is one of
    them."""
    d1, d2, r = q1 - p1, q2 - p2, p1 - p2
    a, e, b = d1 @ d1, d2 @ d2, d1 @ d2
    c, f = d1 @ r, d2 @ r
    denom = a * e - b * b
    parallel = denom <= 1e-12 * a * e + TINY
    s_in = jnp.where(parallel, 0.0, _safe_divide(b * f - c * e, denom))
    t_in = jnp.where(parallel, 0.0, _safe_divide(a * f - b * c, denom))
    return jnp.array(
        [
            [0.0, _clip(_safe_divide(f, e))],
            [1.0, _clip(_safe_divide(f + b, e))],
            [_clip(_safe_divide(-c, a)), 0.0],
            [_clip(_safe_divide(b - c, a)), 1.0],
            [_clip(s_in), _clip(t_in)],
        ]
    )


def _norm(v: Float[Array, " 3"]) -> Float[Array, ""]:
    """``|v|``, 0 with a zero (not NaN, not arbitrary) gradient below
    :data:`CROSSING`."""
    squared = v @ v
    positive = squared > CROSSING
    return jnp.where(positive, jnp.sqrt(jnp.where(positive, squared, 1.0)), 0.0)


def segment_distance(
    p1: Float[Array, " 3"],
    q1: Float[Array, " 3"],
    p2: Float[Array, " 3"],
    q2: Float[Array, " 3"],
) -> Float[Array, ""]:
    """Exact distance between the segments ``p1 q1`` and ``p2 q2`` (module docstring
    for its gradient); a zero-length segment is its point."""
    st = _candidates(p1, q1, p2, q2)

    def gap(s, t):
        return (p1 + s * (q1 - p1)) - (p2 + t * (q2 - p2))

    squared = jax.vmap(lambda x: jnp.sum(gap(*x) ** 2))(st)
    s, t = jax.lax.stop_gradient(st[jnp.argmin(squared)])
    return _norm(gap(s, t))


def capsule_clearance(p1, q1, r1, p2, q2, r2) -> Float[Array, ""]:
    """Clearance of two capsules: segment distance minus the radii (negative when they
    overlap)."""
    return segment_distance(p1, q1, p2, q2) - r1 - r2


def barrier(gap: Float[Array, ...], band) -> Float[Array, ...]:
    """``(max(0, band - gap) / band)²`` (module docstring)."""
    inside = jnp.maximum(band - gap, 0.0) / band
    return inside * inside


def capsule_ends(
    mech: Mechanism, geom: Geometry, state: Float[Array, " S"]
) -> Float[Array, "G 2 3"]:
    """World positions of every capsule's two ends in ``state`` (homogenised)."""
    model = mech.collision
    places = jnp.concatenate([geom.anchors, geom.points])
    bodies = model.segment_bodies
    offsets = jnp.asarray(model.body_offsets) / mech.length_scale
    layers = bodies if model.segment_layers is None else model.segment_layers
    local = (
        places[model.segment_places]
        + offsets[layers][:, None, :]
        - geom.origins[bodies][:, None, :]
    )
    x, q = body_frames(state)
    return x[bodies][:, None, :] + rotate(q[bodies][:, None, :], local)


def capsule_gaps(
    mech: Mechanism, geom: Geometry, state: Float[Array, " S"]
) -> Float[Array, " C"]:
    """Clearance of every checked capsule pair (homogenised)."""
    model = mech.collision
    ends = capsule_ends(mech, geom, state)
    radii = jnp.asarray(model.segment_radii) / mech.length_scale
    i, k = model.capsule_pairs[:, 0], model.capsule_pairs[:, 1]
    return jax.vmap(capsule_clearance)(
        ends[i, 0], ends[i, 1], radii[i], ends[k, 0], ends[k, 1], radii[k]
    )


def collision_value(
    mech: Mechanism, geom: Geometry, state: Float[Array, " S"]
) -> Float[Array, ""]:
    """The collision term of one state: :func:`barrier` summed over the checked
    capsule pairs (module docstring), differentiable in state and design."""
    band = mech.collision.clearance / mech.length_scale
    return jnp.sum(barrier(capsule_gaps(mech, geom, state), band))


def _pair_gaps(mech: Mechanism, geom: Geometry, state):
    """Per checked body pair, the least clearance of its capsule pairs (homogenised),
    and the collision term."""
    model = mech.collision
    gaps = capsule_gaps(mech, geom, state)
    by_pair = jax.ops.segment_min(
        gaps, jnp.asarray(model.capsule_owners), num_segments=len(model.pairs)
    )
    band = model.clearance / mech.length_scale
    return by_pair, jnp.sum(barrier(gaps, band))


@jit
def _clearances(mech: Mechanism, state, design):
    geom = geometry(mech, design_vector(mech, design))
    state = jnp.asarray(state, dtype=jnp.float64)
    fn = partial(_pair_gaps, mech, geom)
    return fn(state) if state.ndim == 1 else jax.vmap(fn)(state)


@dataclass(frozen=True)
class Clearance:
    """Clearance of ``N`` states (file units): ``minimum`` the least over the checked
    body pairs (``inf`` when none is checked), ``worst`` the index of that pair in
    ``Collision.pairs`` (-1 when none), ``value`` the collision term, ``by_pair``
    each checked pair's least clearance."""

    minimum: Float[np.ndarray, " N"]
    worst: Int[np.ndarray, " N"]
    value: Float[np.ndarray, " N"]
    by_pair: Float[np.ndarray, "N Q"]


def has_collision(mech: Mechanism) -> bool:
    """Whether the file has ``[collision]`` with ``enable`` true."""
    return mech.collision is not None and mech.collision.enabled


def pair_names(mech: Mechanism, index: int) -> tuple[str, str]:
    """Body names of checked pair ``index``."""
    a, b = mech.collision.pairs[int(index)]
    return mech.body_names[a], mech.body_names[b]


def clearance(mech: Mechanism, states, *, design=None) -> Clearance:
    """:class:`Clearance` of a batch of homogenised states ``(N, S)`` of ``design``
    (file units, None: the file's): one jitted, vmapped program run in fixed blocks
    (:mod:`.blocks`), kept apart from the evaluation's. :class:`InputError` when the
    file has no ``[collision]`` table or the states have the wrong shape."""
    if mech.collision is None:
        raise InputError(f"{mech.source}: clearance needs a [collision] table")
    states = np.asarray(states, dtype=np.float64)
    if states.ndim != 2 or states.shape[1] != mech.state_size:
        raise InputError(
            f"states: expected (N, {mech.state_size}) homogenised states, got "
            f"{states.shape}"
        )
    count, pairs = len(states), len(mech.collision.pairs)
    if count == 0 or pairs == 0:
        return Clearance(
            np.full(count, np.inf),
            np.full(count, -1),
            np.zeros(count),
            np.zeros((count, pairs)),
        )
    design = design_array(mech, design)

    def run(s):
        return programs.call("clearance", mech, _clearances, s, design)

    by_pair, value = in_blocks(run, (states,))
    by_pair = np.asarray(by_pair) * mech.length_scale
    worst = np.argmin(by_pair, axis=1)
    minimum = by_pair[np.arange(count), worst]
    return Clearance(minimum, worst, np.asarray(value), by_pair)
