"""Swept-area bounds SV^over and SV^app of the distal links (paper 002, Sec. III-B,
III-D).

Every bound is a convex set, represented by its support function sampled on ``K`` unit
directions ``u_k``; the signed distance of a point ``x`` to such a set is taken as
``max_k (u_k·x − h(u_k))``. With finitely many directions this never exceeds the true
distance outside the set, so a clearance constraint ``sd(c_o) >= r_o + Δ/2`` on it
implies the exact eqs. 3-4 (centre outside, every edge farther than the radius), with
the link radius Δ/2 added as in the verification of Sec. III-F.

* ``over``: the paper's SV_1^over (the disk of radius ``r_{n-1}`` about ``s_{n-1}``) and
  SV_2^over (hull of the primitive and its tangents ``h_1, h_2`` to that disk) together
  form the convex hull of disk ∪ SP_j; that hull is one set here.
* ``app``: the elbow arc ``e_j`` runs between the extreme elbow angles at the critical
  points (we also evaluate 8 evenly spaced path points so that the angle unwrapping is
  unambiguous, e.g. for circles around ``s_{n-1}``). SV_1^app is the hull of ``s_{n-1}``
  and a polygon circumscribing ``e_j``; SV_2^app the hull of that polygon and SP_j. The
  paper's pentagon circumscribes the arc with 2 tangent pieces; we use 4, which stays
  bounded for elbow arcs up to 2π and is tighter. As in the paper this is an
  approximation (the elbow may leave ``e_j`` between critical points), hence
  verification.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from ... import _config  # noqa: F401  (float64 on before any array)
from ..._errors import InputError
from . import geometry as geo
from .task import Primitive

DIRECTIONS = 96
ARC_PIECES = 4
EXTRA_SAMPLES = 8
ANGLE_TEMP = 0.01
_ANG = np.linspace(0.0, 2 * np.pi, DIRECTIONS, endpoint=False)
DIRS = np.stack([np.cos(_ANG), np.sin(_ANG)], axis=1)


def signed_distance(
    x: Float[Array, "... 2"], h: Float[Array, " K"], temp: float = 0.0
) -> Float[Array, ...]:
    """Lower bound of the signed distance from ``x`` to the set with support values
    ``h``.

    ``temp > 0`` replaces the max by ``temp·logsumexp(·/temp) − temp·log K``, which is
    smooth (for SLSQP) and still never above the max, so the bound stays conservative.
    """
    z = x @ DIRS.T - h
    if temp <= 0:
        return jnp.max(z, axis=-1)
    return temp * jax.scipy.special.logsumexp(z / temp, axis=-1) - temp * np.log(
        DIRECTIONS
    )


def hull_support(pts: Float[Array, "M 2"], temp: float = 0.0) -> Float[Array, " K"]:
    """Support values of conv(pts); with ``temp > 0`` a smooth upper bound (logsumexp),
    which only enlarges the set."""
    z = pts @ DIRS.T
    if temp <= 0:
        return jnp.max(z, axis=0)
    return temp * jax.scipy.special.logsumexp(z / temp, axis=0)


def over_support(
    prim: Primitive, origin: Float[Array, 2], a
) -> list[Float[Array, " K"]]:
    """SV^over_j: support of conv(disk(s_{n-1}, r_{n-1}) ∪ SP_j) (Sec. III-B)."""
    return [jnp.maximum(geo.support(prim, DIRS), DIRS @ origin + a)]


def elbow_arc(
    prim: Primitive, origin: Float[Array, 2], a, b, sigma, temp: float = 0.0
) -> tuple[Float[Array, ""], Float[Array, ""]]:
    """Angular interval ``[lo, hi]`` of the elbow arc e_j about ``s_{n-1}``
    (Sec. III-D); ``temp > 0`` (radians) takes soft extremes, which only widen the
    interval."""
    t = jnp.concatenate(
        [
            geo.critical_parameters(prim, origin),
            jnp.linspace(0.0, 1.0, EXTRA_SAMPLES + 2)[1:-1],
        ]
    )
    t = jnp.sort(t)
    elbows = geo.ik_elbow(origin, a, b, geo.points(prim, t), sigma)
    ang = jnp.arctan2(elbows[:, 1] - origin[1], elbows[:, 0] - origin[0])
    step = jnp.diff(ang)
    step = jnp.arctan2(jnp.sin(step), jnp.cos(step))
    unwrapped = ang[0] + jnp.concatenate([jnp.zeros(1), jnp.cumsum(step)])
    if temp > 0:
        lse = jax.scipy.special.logsumexp
        lo, hi = -temp * lse(-unwrapped / temp), temp * lse(unwrapped / temp)
    else:
        lo, hi = jnp.min(unwrapped), jnp.max(unwrapped)
    return lo, jnp.minimum(hi, lo + 2 * jnp.pi)


def arc_polygon(origin: Float[Array, 2], a, lo, hi) -> Float[Array, "P 2"]:
    """Vertices of the polygon circumscribing the arc ``[lo, hi]`` of radius ``a``:
    the two end points and ``ARC_PIECES`` tangent-line intersections at radius
    ``a / cos(δ/2)``, ``δ = (hi − lo)/ARC_PIECES``."""
    delta = (hi - lo) / ARC_PIECES
    mids = lo + (jnp.arange(ARC_PIECES) + 0.5) * delta
    outer = origin + (a / jnp.cos(0.5 * delta)) * geo.unit(mids)
    ends = origin + a * geo.unit(jnp.stack([lo, hi]))
    return jnp.concatenate([ends[:1], outer, ends[1:]])


def app_support(
    prim: Primitive, origin: Float[Array, 2], a, b, sigma, temp: float = 0.0
) -> list[Float[Array, " K"]]:
    """SV^app_j = (SV_1^app, SV_2^app) as support values (Sec. III-D, Fig. 4)."""
    lo, hi = elbow_arc(prim, origin, a, b, sigma, ANGLE_TEMP if temp else 0.0)
    poly = arc_polygon(origin, a, lo, hi)
    sv1 = hull_support(jnp.concatenate([origin[None], poly]), temp)
    sv2 = jnp.maximum(hull_support(poly, temp), geo.support(prim, DIRS))
    return [sv1, sv2]


BOUNDS = ("over", "app")


def swept_support(
    kind: str, prim: Primitive, origin, a, b, sigma, temp: float = 0.0
) -> list[Float[Array, " K"]]:
    """The bound named ``kind`` (``"over"`` or ``"app"``) as a list of convex parts;
    ``temp`` smooths maxima into upper bounds (see :func:`hull_support`)."""
    if kind == "over":
        return over_support(prim, origin, a)
    if kind == "app":
        return app_support(prim, origin, a, b, sigma, temp)
    raise InputError(
        f"swept: unknown swept-area bound {kind!r}; expected one of {list(BOUNDS)}"
    )


def outline(h: Float[Array, " K"]) -> Float[np.ndarray, "K 2"]:
    """Polygon of a convex set from its sampled support values (for plots): the
    intersection of consecutive supporting half-planes ``u_k·x <= h_k``."""
    h = np.asarray(h)
    u0, u1 = DIRS, np.roll(DIRS, -1, axis=0)
    h0, h1 = h, np.roll(h, -1)
    det = u0[:, 0] * u1[:, 1] - u0[:, 1] * u1[:, 0]
    x = (h0 * u1[:, 1] - h1 * u0[:, 1]) / det
    y = (u0[:, 0] * h1 - u1[:, 0] * h0) / det
    return np.stack([x, y], axis=1)
