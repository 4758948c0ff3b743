"""Rotations: unit quaternions (layout ``wxyz``, shape ``(..., 4)``), matrices
``(..., 3, 3)``, axis-angle and rotation vectors (the exponential map).

A body's orientation ``q = (w, x, y, z)`` maps body-local vectors to world vectors,
``v_world = R(q) v_local``; ``p ⊗ q`` rotates by ``q`` first. Nothing here normalises a
quaternion in traced code: the constraint system carries one unit-norm row per
quaternion, so states off the unit sphere during a solve are allowed and
:func:`rotate` is the exact quadratic form (it scales by ``|q|^2``), which keeps the
solver's functions polynomial and NaN-free for reverse-mode AD. The maps with a
square root or a division (:func:`quaternion_exp`, :func:`quaternion_log`,
:func:`matrix_exp`) are guarded at the zero rotation, so neither they nor their
derivatives give NaN there.

Two halves, one formula each: the functions without prefix are JAX (traced code); those
prefixed ``np_`` are numpy, for file-time code (exporters, the loader's symmetry
reader), which the command line runs without importing JAX: this module imports
``jax.numpy`` inside the JAX functions, not at the top. :func:`unit` and
:func:`turn_onto` take the array module as their first argument, for code that runs
both ways (:mod:`.following`).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
from jaxtyping import Float

if TYPE_CHECKING:  # jaxtyping's ``Array`` is ``jax.Array``: importing it imports JAX
    from jaxtyping import Array

#: Below this squared sine of a half angle (or squared angle) a map uses its Taylor
#: series: the leading term is exact to float64 there.
_SMALL = 1e-24


def _jnp():
    import jax.numpy as jnp

    return jnp


def _hat(xp, v: Float[Array, "... 3"]) -> Float[Array, "... 3 3"]:
    """The cross-product matrix ``[v]×`` (``[v]× u = v × u``)."""
    x, y, z = v[..., 0], v[..., 1], v[..., 2]
    zero = xp.zeros_like(x)
    rows = [
        xp.stack([zero, -z, y], axis=-1),
        xp.stack([z, zero, -x], axis=-1),
        xp.stack([-y, x, zero], axis=-1),
    ]
    return xp.stack(rows, axis=-2)


def _rodrigues(xp, k, sine, versine) -> Float[Array, "... 3 3"]:
    """``I + sine [k]× + versine [k]×²`` (Rodrigues' formula)."""
    hat = _hat(xp, k)
    return (
        xp.eye(3) + sine[..., None, None] * hat + versine[..., None, None] * (hat @ hat)
    )


def _matrix(xp, q: Float[Array, "... 4"]) -> Float[Array, "... 3 3"]:
    """``R(q)`` of a unit quaternion."""
    w, x, y, z = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    rows = [
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ]
    return xp.stack([xp.stack(row, axis=-1) for row in rows], axis=-2)


def _np_rotate(q: np.ndarray, v: np.ndarray) -> np.ndarray:
    """:func:`rotate` in numpy (the same quadratic form)."""
    w, u = q[0], q[1:]
    return (w * w - u @ u) * v + 2.0 * (u @ v) * u + 2.0 * w * np.cross(u, v)


def _quadratic() -> np.ndarray:
    """:data:`QUADRATIC`, by polarisation of :func:`rotate` on the basis quaternions."""
    eye4, eye3 = np.eye(4), np.eye(3)

    def entries(q):  # (3, 3): column j is R(q) e_j
        return np.stack([_np_rotate(q, e) for e in eye3], axis=1)

    out = np.zeros((3, 3, 4, 4))
    for a in range(4):
        for b in range(4):
            both = entries(eye4[a] + eye4[b]) - entries(eye4[a]) - entries(eye4[b])
            out[:, :, a, b] = 0.5 * both if a != b else entries(eye4[a])
    return out


#: ``Q`` ``(3, 3, 4, 4)``, symmetric in its last two axes, entries in {0, ±1}: the
#: matrix of :func:`rotate` is ``R_ij(q) = qᵀ Q_ij q`` for every ``q`` (for a non-unit
#: ``q``, ``|q|²`` times a rotation), so ``∂R_ij/∂q = 2 Q_ij q``.
QUADRATIC = _quadratic()
#: ``R = (q ⊗ q) · _SQUARES`` with ``q ⊗ q`` flattened to 16: ``(16, 9)``.
_SQUARES = QUADRATIC.reshape(9, 16).T.copy()


# ---- JAX: traced code ---------------------------------------------------------------


def quadratic_matrix(q: Float[Array, "... 4"]) -> Float[Array, "... 3 3"]:
    """The matrix of :func:`rotate`: ``quadratic_matrix(q) @ v == rotate(q, v)`` for
    any ``q`` (``|q|² R(q / |q|)``), one product of ``q ⊗ q`` with a constant."""
    jnp = _jnp()
    lead = q.shape[:-1]
    squares = (q[..., :, None] * q[..., None, :]).reshape(lead + (16,))
    return (squares @ jnp.asarray(_SQUARES)).reshape(lead + (3, 3))


def rotate(q: Float[Array, "... 4"], v: Float[Array, "... 3"]) -> Float[Array, "... 3"]:
    """``R(q) v = (w² - u·u) v + 2 (u·v) u + 2 w (u × v)`` with ``q = (w, u)``.

    Exact rotation for unit ``q``; for other ``q`` it is the same quadratic form, scaled
    by ``|q|²``.
    """
    jnp = _jnp()
    w = q[..., :1]
    u = q[..., 1:]
    uu = jnp.sum(u * u, axis=-1, keepdims=True)
    uv = jnp.sum(u * v, axis=-1, keepdims=True)
    return (w * w - uu) * v + 2.0 * uv * u + 2.0 * w * jnp.cross(u, v)


def multiply(
    p: Float[Array, "... 4"], q: Float[Array, "... 4"]
) -> Float[Array, "... 4"]:
    """Hamilton product ``p ⊗ q``."""
    jnp = _jnp()
    pw, pv = p[..., :1], p[..., 1:]
    qw, qv = q[..., :1], q[..., 1:]
    w = pw * qw - jnp.sum(pv * qv, axis=-1, keepdims=True)
    v = pw * qv + qw * pv + jnp.cross(pv, qv)
    return jnp.concatenate([w, v], axis=-1)


def conjugate(q: Float[Array, "... 4"]) -> Float[Array, "... 4"]:
    """Conjugate ``(w, -x, -y, -z)``; the inverse rotation for unit ``q``."""
    return q * _jnp().array([1.0, -1.0, -1.0, -1.0])


def from_axis_angle(
    axis: Float[Array, "... 3"], angle: Float[Array, ...]
) -> Float[Array, "... 4"]:
    """Unit quaternion of a rotation by ``angle`` (rad) about the unit vector
    ``axis``."""
    jnp = _jnp()
    half = 0.5 * jnp.asarray(angle)[..., None]
    return jnp.concatenate([jnp.cos(half), jnp.sin(half) * axis], axis=-1)


def matrix(q: Float[Array, "... 4"]) -> Float[Array, "... 3 3"]:
    """``R(q)`` of a unit quaternion."""
    return _matrix(_jnp(), q)


def axis_angle_matrix(
    axis: Float[Array, "... 3"], angle: Float[Array, ...]
) -> Float[Array, "... 3 3"]:
    """``R`` of a rotation by ``angle`` (rad) about the unit vector ``axis``."""
    jnp = _jnp()
    angle = jnp.asarray(angle)
    return _rodrigues(jnp, jnp.asarray(axis), jnp.sin(angle), 1.0 - jnp.cos(angle))


def matrix_exp(omega: Float[Array, "... 3"]) -> Float[Array, "... 3 3"]:
    """``exp([ω]×)``: the rotation by ``|ω|`` about ``ω``; finite, with finite
    derivatives, at ``ω = 0``."""
    jnp = _jnp()
    square = jnp.sum(omega * omega, axis=-1)
    small = square < 1e-8  # below |ω| = 1e-4 the series to ω⁴ is exact to float64
    safe = jnp.where(small, 1.0, square)
    theta = jnp.sqrt(safe)
    sine = jnp.where(
        small, 1.0 - square / 6.0 + square**2 / 120.0, jnp.sin(theta) / theta
    )
    versine = jnp.where(
        small, 0.5 - square / 24.0 + square**2 / 720.0, (1.0 - jnp.cos(theta)) / safe
    )
    return _rodrigues(jnp, omega, sine, versine)


def quaternion_exp(omega: Float[Array, "... 3"]) -> Float[Array, "... 4"]:
    """The unit quaternion of the rotation vector ``ω`` (the rotation by ``|ω|`` about
    ``ω``); NaN-free with its derivatives at ``ω = 0``."""
    jnp = _jnp()
    square = jnp.sum(omega * omega, axis=-1, keepdims=True)
    small = square < _SMALL
    theta = jnp.sqrt(jnp.where(small, 1.0, square))
    scale = jnp.where(small, 0.5 - square / 48.0, jnp.sin(0.5 * theta) / theta)
    w = jnp.where(small, 1.0 - square / 8.0, jnp.cos(0.5 * theta))
    return jnp.concatenate([w, scale * omega], axis=-1)


def quaternion_log(q: Float[Array, "... 4"]) -> Float[Array, "... 3"]:
    """The rotation vector (angle in ``[0, π]``) of the unit quaternion ``q``; ``q`` and
    ``-q`` give the same; NaN-free with its derivatives at the identity."""
    jnp = _jnp()
    q = jnp.where(q[..., :1] < 0.0, -q, q)
    w, u = q[..., :1], q[..., 1:]
    square = jnp.sum(u * u, axis=-1, keepdims=True)
    small = square < _SMALL
    sine = jnp.sqrt(jnp.where(small, 1.0, square))
    scale = jnp.where(small, 2.0 / w, 2.0 * jnp.arctan2(sine, w) / sine)
    return scale * u


# ---- either half: ``xp`` is numpy or jax.numpy ------------------------------------


def unit(xp, v: Float[Array, "... 3"]) -> Float[Array, "... 3"]:
    """``v / |v|``, and ``v`` (zero) where ``|v| = 0`` (an unused axis, e.g. the second
    axis of a joint that has none). The square root never sees that zero, so its
    derivative holds no ``0 · inf`` and a zero cotangent gives a zero gradient, not
    NaN (the partial gradient pulls every field of the geometry back)."""
    square = xp.sum(v * v, axis=-1, keepdims=True)
    return v / xp.sqrt(xp.where(square > 0.0, square, 1.0))


def turn_onto(
    xp, u: Float[Array, "... 3"], v: Float[Array, "... 3"], d: Float[Array, "... 3"]
) -> Float[Array, "... 3"]:
    """``d`` turned by the smallest rotation taking the unit ``u`` onto the unit ``v``
    (Rodrigues about ``k = u × v`` with ``cos = u · v``, ``sin = |k|``; not for
    ``v = -u``)."""
    k, c = xp.cross(u, v), xp.sum(u * v, axis=-1, keepdims=True)
    kd = xp.sum(k * d, axis=-1, keepdims=True)
    return c * d + xp.cross(k, d) + k * kd / (1.0 + c)


# ---- numpy: file-time code ----------------------------------------------------------


def np_matrix(q: Float[np.ndarray, "... 4"]) -> Float[np.ndarray, "... 3 3"]:
    """``R(q / |q|)``."""
    q = np.asarray(q, dtype=float)
    return _matrix(np, q / np.linalg.norm(q, axis=-1, keepdims=True))


def np_axis_angle_matrix(
    axis: Float[np.ndarray, " 3"], angle: float
) -> Float[np.ndarray, "3 3"]:
    """``R`` of a rotation by ``angle`` (rad) about the unit vector ``axis``."""
    angle = np.asarray(angle, dtype=float)
    return _rodrigues(np, np.asarray(axis, float), np.sin(angle), 1.0 - np.cos(angle))


def np_from_matrix(r: Float[np.ndarray, "3 3"]) -> Float[np.ndarray, " 4"]:
    """The unit quaternion ``wxyz`` with ``w ≥ 0`` of a rotation matrix (Shepperd's
    method: from the largest of the trace and the diagonal, so no division is small)."""
    trace = np.trace(r)
    k = int(np.argmax([trace, r[0, 0], r[1, 1], r[2, 2]]))
    if k == 0:
        s = 2.0 * np.sqrt(1.0 + trace)
        q = [
            s / 4,
            (r[2, 1] - r[1, 2]) / s,
            (r[0, 2] - r[2, 0]) / s,
            (r[1, 0] - r[0, 1]) / s,
        ]
    else:
        i, j, m = k - 1, k % 3, (k + 1) % 3
        s = 2.0 * np.sqrt(1.0 + r[i, i] - r[j, j] - r[m, m])
        q = [0.0] * 4
        q[0] = (r[m, j] - r[j, m]) / s
        q[1 + i] = s / 4
        q[1 + j] = (r[j, i] + r[i, j]) / s
        q[1 + m] = (r[m, i] + r[i, m]) / s
    q = np.array(q)
    return q if q[0] >= 0 else -q


def np_rpy(r: Float[np.ndarray, "3 3"]) -> Float[np.ndarray, " 3"]:
    """Roll, pitch, yaw of ``R = Rot_z(yaw) Rot_y(pitch) Rot_x(roll)``, pitch in
    ``[-π/2, π/2]``."""
    return np.array(
        [
            np.arctan2(r[2, 1], r[2, 2]),
            np.arctan2(-r[2, 0], np.hypot(r[2, 1], r[2, 2])),
            np.arctan2(r[1, 0], r[0, 0]),
        ]
    )
