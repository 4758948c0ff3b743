"""One residual function per joint family, for a single joint instance.

Every function takes the two bodies' homogenised states ``(x_i, q_i)``, ``(x_j, q_j)``
and the joint's rest geometry, and returns its rows (paper Sec. II-A). Body-local
quantities are rest world quantities minus the body origin, since rest orientations
are the identity. Rows are polynomial in the state (no normalisation), so they are
smooth everywhere.

* point coincidence (3): ``x_i + R_i r_i - (x_j + R_j r_j)``
* axis alignment (2): ``(R_i n)·(R_j u)``, ``(R_i n)·(R_j w)`` with ``w = n × u``
* twist lock (1): ``(R_i u)·(R_j w)`` (no relative rotation about ``n``)
* slide lock (2): ``d·(R_i u)``, ``d·(R_i w)``, ``d`` the anchor separation
"""

from __future__ import annotations

import jax.numpy as jnp
from jaxtyping import Array, Float

from .. import _config  # noqa: F401  (float64 on before any array)
from .rotations import quadratic_matrix, rotate

Vec = Float[Array, "3"]
Quat = Float[Array, "4"]


def anchor_separation(xi: Vec, qi: Quat, ri: Vec, xj: Vec, qj: Quat, rj: Vec) -> Vec:
    """World vector from the anchor on body i to the anchor on body j."""
    return (xj + rotate(qj, rj)) - (xi + rotate(qi, ri))


def _axis_rows(qi: Quat, qj: Quat, n: Vec, u: Vec) -> Float[Array, 2]:
    ni = rotate(qi, n)
    w = jnp.cross(n, u)
    return jnp.stack([ni @ rotate(qj, u), ni @ rotate(qj, w)])


def _twist_row(qi: Quat, qj: Quat, n: Vec, u: Vec) -> Float[Array, 1]:
    return jnp.stack([rotate(qi, u) @ rotate(qj, jnp.cross(n, u))])


def _slide_rows(d: Vec, qi: Quat, n: Vec, u: Vec) -> Float[Array, 2]:
    return jnp.stack([d @ rotate(qi, u), d @ rotate(qi, jnp.cross(n, u))])


def revolute(xi, qi, ri, xj, qj, rj, n, u, n2) -> Float[Array, 5]:
    """Revolute: common point and common axis ``n`` (5 rows)."""
    d = anchor_separation(xi, qi, ri, xj, qj, rj)
    return jnp.concatenate([d, _axis_rows(qi, qj, n, u)])


def spherical(xi, qi, ri, xj, qj, rj, n, u, n2) -> Float[Array, 3]:
    """Spherical (ball): common point (3 rows)."""
    return anchor_separation(xi, qi, ri, xj, qj, rj)


def universal(xi, qi, ri, xj, qj, rj, n, u, n2) -> Float[Array, 4]:
    """Universal: common point, axis ``n`` on body i stays ⟂ to axis ``n2`` on body j
    (4)."""
    d = anchor_separation(xi, qi, ri, xj, qj, rj)
    return jnp.concatenate([d, jnp.stack([rotate(qi, n) @ rotate(qj, n2)])])


def prismatic(xi, qi, ri, xj, qj, rj, n, u, n2) -> Float[Array, 5]:
    """Prismatic: no relative rotation, translation only along ``n`` (5 rows)."""
    d = anchor_separation(xi, qi, ri, xj, qj, rj)
    return jnp.concatenate(
        [_axis_rows(qi, qj, n, u), _twist_row(qi, qj, n, u), _slide_rows(d, qi, n, u)]
    )


def cylindrical(xi, qi, ri, xj, qj, rj, n, u, n2) -> Float[Array, 4]:
    """Cylindrical: rotation about and translation along ``n`` only (4 rows)."""
    d = anchor_separation(xi, qi, ri, xj, qj, rj)
    return jnp.concatenate([_axis_rows(qi, qj, n, u), _slide_rows(d, qi, n, u)])


def fixed(xi, qi, ri, xj, qj, rj, n, u, n2) -> Float[Array, 6]:
    """Fixed (weld): common point and no relative rotation (6 rows).

    Fixed joints need a reference frame: their ``n``/``u`` come from the file's axis if
    given, else the loader supplies ``n = z``.
    """
    d = anchor_separation(xi, qi, ri, xj, qj, rj)
    return jnp.concatenate([d, _axis_rows(qi, qj, n, u), _twist_row(qi, qj, n, u)])


def relative_angle(qi: Quat, qj: Quat, n: Vec, u: Vec) -> Float[Array, ""]:
    """Rotation of body j relative to body i about ``n`` (rad, right-hand rule), in (-π,
    π].

    The angle of ``R_j u`` in the plane spanned by ``R_i u`` and ``R_i (n × u)``; zero
    at rest.
    """
    uj = rotate(qj, u)
    return jnp.arctan2(uj @ rotate(qi, jnp.cross(n, u)), uj @ rotate(qi, u))


def angle_error(
    qi: Quat, qj: Quat, n: Vec, u: Vec, target: Float[Array, ""]
) -> Float[Array, ""]:
    """``relative_angle - target`` wrapped to (-π, π] (paper footnote 1), smooth near
    0."""
    uj = rotate(qj, u)
    c = uj @ rotate(qi, u)
    s = uj @ rotate(qi, jnp.cross(n, u))
    ct, st = jnp.cos(target), jnp.sin(target)
    return jnp.arctan2(s * ct - c * st, c * ct + s * st)


def tait_bryan(qi: Quat, qj: Quat, e1: Vec, e2: Vec) -> Float[Array, 3]:
    """Intrinsic angles ``(θ1, θ2, θ3)`` of body j relative to body i with
    ``R_iᵀ R_j = Rot(e1, θ1) Rot(e2, θ2) Rot(e1 × e2, θ3)`` (rest axes, ``e1 ⟂ e2``);
    zero at rest.

    With ``M_ab = (R_i e_a)·(R_j e_b)`` the relative rotation in the joint's frame,
    ``θ1 = atan2(-M₂₃, M₃₃)``, ``θ2 = atan2(M₁₃, √(M₁₁² + M₁₂²))``,
    ``θ3 = atan2(-M₁₂, M₁₁)``; the angles are defined for ``|θ2| < π/2`` (gimbal lock at
    ``±π/2``). ``M`` is one product of the two bodies' matrices
    (:func:`~.rotations.quadratic_matrix`, the form of :func:`~.rotations.rotate`, so
    for non-unit quaternions too), not nine dots of six rotated vectors. For a
    universal joint with ``e1 = n`` on body i and ``e2 = n2`` on body
    j, ``θ3 ≡ 0`` and ``θ1``, ``θ2`` are its two joint angles.
    """
    frame = jnp.stack([e1, e2, jnp.cross(e1, e2)], axis=1)  # columns e_a
    m = (quadratic_matrix(qi) @ frame).T @ (quadratic_matrix(qj) @ frame)
    m11, m12, m13 = m[0, 0], m[0, 1], m[0, 2]
    first = jnp.arctan2(-m[1, 2], m[2, 2])
    second = jnp.arctan2(m13, jnp.sqrt(m11 * m11 + m12 * m12))
    third = jnp.arctan2(-m12, m11)
    return jnp.stack([first, second, third])


#: Below this ``sin θ`` (θ the tilt of :func:`direction_angles`), ``θ / sin θ`` is its
#: series, so the angles and their derivatives stay finite at rest.
_SMALL_TILT = 1e-6


def direction_angles(qi: Quat, qj: Quat, d: Vec, e1: Vec) -> Float[Array, 2]:
    """The tilt ``(τ1, τ2)`` of body j's axis ``d`` relative to body i: the
    components along ``e1`` and ``e2 = d × e1`` of the rotation vector of the
    shortest rotation taking ``d`` to ``v = R_iᵀ R_j d`` (rest axes, ``e1 ⟂ d``);
    zero at rest.

    With ``v = c0 d + c1 e1 + c2 e2``, ``s = √(c1² + c2²) = sin θ`` and
    ``θ = atan2(s, c0)`` the angle between ``d`` and ``v``:
    ``(τ1, τ2) = (θ / s) (-c2, c1)``. A rotation by α about ``e1`` gives ``(α, 0)``,
    one about ``e2`` ``(0, α)``; a spin about ``d`` gives ``(0, 0)``. Smooth wherever
    ``θ < π`` (the only singular direction is ``-d``); below ``s`` = 1e-6,
    ``θ / s = (1 - s² / 3c0²) / c0`` (the series of ``atan x / x``), so rest has
    exact, finite derivatives.
    """
    a = rotate(qj, d)
    c0 = rotate(qi, d) @ a
    c1 = rotate(qi, e1) @ a
    c2 = rotate(qi, jnp.cross(d, e1)) @ a
    s2 = c1 * c1 + c2 * c2
    small = (s2 < _SMALL_TILT**2) & (c0 > 0)
    s = jnp.sqrt(jnp.where(small, 1.0, s2))
    c0_safe = jnp.where(small, c0, 1.0)
    ratio = jnp.where(
        small,
        (1.0 - s2 / (3.0 * c0_safe * c0_safe)) / c0_safe,
        jnp.arctan2(s, c0) / s,
    )
    return ratio * jnp.stack([-c2, c1])


def wrap(angle: Float[Array, ...]) -> Float[Array, ...]:
    """``angle`` wrapped to (-π, π], smooth away from ±π."""
    return jnp.arctan2(jnp.sin(angle), jnp.cos(angle))


def slide(xi, qi, ri, xj, qj, rj, n) -> Float[Array, ""]:
    """Translation of the anchor on body j relative to body i along ``R_i n``; zero at
    rest."""
    return anchor_separation(xi, qi, ri, xj, qj, rj) @ rotate(qi, n)


FAMILIES = {
    "revolute": revolute,
    "spherical": spherical,
    "universal": universal,
    "prismatic": prismatic,
    "cylindrical": cylindrical,
    "fixed": fixed,
}
