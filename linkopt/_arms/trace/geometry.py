"""Planar geometry of shape primitives and 2-/3-link arms (paper 002, Sec. II, III-C,
Table I).

Pure array functions, differentiable in the origin, link lengths and angles; a
:class:`~linkopt._arms.trace.task.Primitive` is static (its numbers are constants at
trace time). Inside a JAX trace (the synthesis' jitted constraints) they are
``jax.numpy``; called on concrete arrays (verification, export, figures) they are the
same operations in numpy (:func:`_xp`), which run at once where ``jax.numpy``
compiled a small program for each operation and shape (a small task's ``linkopt arm
trace`` compiled some four hundred).

Conventions: the elbow branch ``sigma = +1`` puts the elbow to the *left* of the
vector from the distal origin ``s_{n-1}`` to the end-effector (the paper's "upwards"
configuration, positive cross product in eq. 5), ``sigma = -1`` to the right.
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from ..._config import traced
from .task import Primitive

TINY = 1e-30  # keeps sqrt differentiable at 0 without biasing lengths >= 1e-15


def _xp(*arrays):
    """``jax.numpy`` where any of ``arrays`` is traced, else numpy."""
    return jnp if traced(*arrays) else np


def _norm(v: Float[Array, "... 2"]) -> Float[Array, ...]:
    """NaN-safe Euclidean norm (zero gradient at 0 rather than NaN)."""
    xp = _xp(v)
    return xp.sqrt(xp.sum(v * v, axis=-1) + TINY)


def unit_vector(v: Float[Array, 2]) -> Float[Array, 2]:
    """``v / |v|``, and the x-axis for ``v = 0`` (where every direction is as good, e.g.
    a circle seen from its centre), with finite gradients everywhere."""
    xp = _xp(v)
    n2 = xp.sum(v * v)
    safe = n2 > 1e-30
    return xp.where(safe, v / xp.sqrt(xp.where(safe, n2, 1.0)), xp.array([1.0, 0.0]))


def cross(a: Float[Array, "... 2"], b: Float[Array, "... 2"]) -> Float[Array, ...]:
    return a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]


def unit(angle: Float[Array, ...]) -> Float[Array, "... 2"]:
    xp = _xp(angle)
    return xp.stack([xp.cos(angle), xp.sin(angle)], axis=-1)


def points(prim: Primitive, t: Float[Array, " N"]) -> Float[Array, "N 2"]:
    """``p(t)`` of Table I for ``t ∈ [0, 1]`` (lines affine, arcs/circles by angle)."""
    t = _xp(t).asarray(t)
    if prim.kind == "line":
        return prim.start + t[:, None] * (prim.end - prim.start)
    return prim.center + prim.radius * unit(prim.angle0 + prim.sweep * t)


def arc_parameter(
    prim: Primitive, p: Float[Array, "... 2"]
) -> tuple[Float[Array, ...], Float[Array, ...]]:
    """For a point on an arc/circle's circle: its parameter ``t`` (may exceed 1) and
    whether it lies on the arc (``0 <= t <= 1``)."""
    xp = _xp(p)
    d = p - prim.center
    ang = xp.arctan2(d[..., 1], d[..., 0])
    offset = xp.mod((ang - prim.angle0) * np.sign(prim.sweep), 2 * np.pi)
    offset = xp.where(offset > 2 * np.pi - 1e-9, 0.0, offset)  # the start, past 2π
    t = offset / abs(prim.sweep)
    return t, t <= 1.0 + 1e-12


def critical_points(
    prim: Primitive, origin: Float[Array, 2]
) -> dict[str, Float[Array, 2]]:
    """Critical points of Table I relative to the distal origin ``s_{n-1}``.

    Returns ``initial``, ``final``, ``closest``, ``farthest`` (a circle's initial and
    final point are its start ``c.p_c``). Lines: the foot of the perpendicular clamped
    to the segment, the farther end point. Circles: ``c ∓ r (s - c)/|s - c|``. Arcs:
    those two points when they lie on the arc, else the nearer/farther end point.
    """
    xp = _xp(origin)
    cands, valid = _candidates(prim, origin)
    dist = _norm(cands - origin)
    big = 1e30
    closest = cands[xp.argmin(xp.where(valid, dist, big))]
    farthest = cands[xp.argmax(xp.where(valid, dist, -big))]
    return {
        "initial": xp.asarray(prim.start),
        "final": xp.asarray(prim.end),
        "closest": closest,
        "farthest": farthest,
    }


def _candidates(
    prim: Primitive, origin: Float[Array, 2]
) -> tuple[Float[Array, "K 2"], Float[Array, " K"]]:
    xp = _xp(origin)
    ends = xp.stack([xp.asarray(prim.start), xp.asarray(prim.end)])
    if prim.kind == "line":
        d = prim.end - prim.start
        s = xp.clip(xp.dot(origin - prim.start, d) / xp.dot(d, d), 0.0, 1.0)
        return xp.concatenate([ends, (prim.start + s * d)[None]]), xp.ones(3, bool)
    u = unit_vector(origin - prim.center)
    ray = xp.stack([prim.center + prim.radius * u, prim.center - prim.radius * u])
    if prim.kind == "circle":
        return ray, xp.ones(2, bool)
    _, on_arc = arc_parameter(prim, ray)
    return xp.concatenate([ends, ray]), xp.concatenate([xp.ones(2, bool), on_arc])


def distance_range(
    prim: Primitive, origin: Float[Array, 2]
) -> tuple[Float[Array, ""], Float[Array, ""]]:
    """``(|p_closest - s|, |p_farthest - s|)``: the radii eq. 2 must bracket."""
    cp = critical_points(prim, origin)
    return _norm(cp["closest"] - origin), _norm(cp["farthest"] - origin)


def critical_parameters(prim: Primitive, origin: Float[Array, 2]) -> Float[Array, 4]:
    """Path parameters ``t`` of (initial, final, closest, farthest); circles end at
    1."""
    xp = _xp(origin)
    cp = critical_points(prim, origin)
    if prim.kind == "line":
        d = prim.end - prim.start
        tt = [
            xp.dot(cp[k] - prim.start, d) / xp.dot(d, d)
            for k in ("closest", "farthest")
        ]
    else:
        tt = [
            xp.clip(arc_parameter(prim, cp[k])[0], 0.0, 1.0)
            for k in ("closest", "farthest")
        ]
    return xp.stack([xp.asarray(0.0), xp.asarray(1.0), *tt])


def support(prim: Primitive, dirs: Float[Array, "K 2"]) -> Float[Array, " K"]:
    """Support function ``h(u) = max_{p ∈ SP} u·p`` of the primitive (exact per
    type)."""
    xp = _xp(dirs)
    ends = xp.maximum(dirs @ prim.start, dirs @ prim.end)
    if prim.kind == "line":
        return ends
    top = dirs @ prim.center + prim.radius
    if prim.kind == "circle":
        return top
    _, on_arc = arc_parameter(prim, prim.center + dirs)
    return xp.where(on_arc, top, ends)


def reachable(
    origin: Float[Array, 2], a, b, p: Float[Array, "... 2"], tol: float = 0.0
) -> Float[Array, ...]:
    """Eq. 2: ``|a - b| <= |p - s| <= a + b`` (the 2-link annulus), with slack
    ``tol``."""
    xp = _xp(origin, a, b, p)
    d = xp.sqrt(xp.sum((p - origin) ** 2, axis=-1))
    return (d >= xp.abs(a - b) - tol) & (d <= a + b + tol)


def ik_elbow(
    origin: Float[Array, 2], a, b, p: Float[Array, "... 2"], sigma
) -> Float[Array, "... 2"]:
    """Closed-form 2-link IK: the elbow ``s_n`` with ``|s_n - s| = a``,
    ``|p - s_n| = b``.

    Law of cosines: the elbow is the direction to ``p`` turned by
    ``sigma · arccos((a² + d² - b²) / (2 a d))``; outside the annulus the cosine is
    clipped (fully stretched/folded), so callers check :func:`reachable` first.
    """
    xp = _xp(origin, a, b, p, sigma)
    v = p - origin
    d = _norm(v)
    cos_a = xp.clip((a * a + d * d - b * b) / (2 * a * d), -1.0 + 1e-12, 1.0 - 1e-12)
    ang = xp.arctan2(v[..., 1], v[..., 0]) + sigma * xp.arccos(cos_a)
    return origin + a * unit(ang)


def arm_states(
    base: Float[Array, 2],
    lengths: Float[Array, " n"],
    proximal_angle,
    p: Float[Array, "N 2"],
    sigma,
) -> Float[Array, "N n+1 2"]:
    """States ``S = (s_1, …, s_{n+1})`` placing the end-effector at each ``p``.

    Two links: ``s_1 = base``, elbow by :func:`ik_elbow`. Three links: the proximal link
    is held at the absolute angle ``proximal_angle`` (Sec. III-A), ``s_2 = base + r_1
    u(angle)``, and the distal pair is solved from ``s_2``.
    """
    xp = _xp(base, lengths, proximal_angle, p, sigma)
    p = xp.atleast_2d(p)
    origin = distal_origin(base, lengths, proximal_angle)
    elbow = ik_elbow(origin, lengths[-2], lengths[-1], p, sigma)
    rows = [xp.broadcast_to(base, p.shape)]
    if lengths.shape[0] == 3:
        rows.append(xp.broadcast_to(origin, p.shape))
    return xp.stack(rows + [elbow, p], axis=1)


def distal_origin(
    base: Float[Array, 2], lengths: Float[Array, " n"], proximal_angle
) -> Float[Array, 2]:
    """``s_{n-1}``: the base for 2 links, the end of the static proximal link for 3."""
    if lengths.shape[0] == 2:
        return _xp(base, lengths).asarray(base)
    return base + lengths[0] * unit(proximal_angle)


def joint_angles(states: Float[Array, "N n+1 2"]) -> Float[Array, "N n"]:
    """DH joint angles: ``θ_1`` from the global x-axis, then each link relative to the
    previous one, wrapped to (-π, π]."""
    xp = _xp(states)
    links = states[:, 1:] - states[:, :-1]
    absolute = xp.arctan2(links[..., 1], links[..., 0])
    rel = xp.concatenate([absolute[:, :1], xp.diff(absolute, axis=1)], axis=1)
    return xp.arctan2(xp.sin(rel), xp.cos(rel))


def forward(
    base: Float[Array, 2], lengths: Float[Array, " n"], angles: Float[Array, "N n"]
) -> Float[Array, "N n+1 2"]:
    """Forward kinematics from DH joint angles (inverse of :func:`joint_angles`)."""
    xp = _xp(base, lengths, angles)
    absolute = xp.cumsum(angles, axis=1)
    steps = lengths * unit(absolute).transpose(2, 0, 1)
    pts = xp.cumsum(steps.transpose(1, 2, 0), axis=1)
    return xp.concatenate(
        [xp.broadcast_to(base, (angles.shape[0], 1, 2)), base + pts], axis=1
    )


def segment_distance(
    x: Float[Array, "... 2"], a: Float[Array, "... 2"], b: Float[Array, "... 2"]
) -> Float[Array, ...]:
    """Distance from points ``x`` to segments ``[a, b]`` (broadcast)."""
    xp = _xp(x, a, b)
    d = b - a
    s = xp.clip(
        xp.sum((x - a) * d, axis=-1) / (xp.sum(d * d, axis=-1) + TINY), 0.0, 1.0
    )
    return _norm(x - (a + s[..., None] * d))
