"""Unit quaternions, layout ``wxyz``, shape ``(..., 4)``.

A body's orientation ``q = (w, x, y, z)`` maps body-local vectors to world vectors,
``v_world = R(q) v_local``. Nothing here normalises: the constraint system carries one
unit-norm row per quaternion, so states off the unit sphere during a solve are allowed
and ``R(q)`` is the exact quadratic form (it scales by ``|q|^2``), which keeps every
function polynomial and NaN-free for reverse-mode AD.
"""

from __future__ import annotations

import jax.numpy as jnp
from jaxtyping import Array, Float


def rotate(q: Float[Array, "... 4"], v: Float[Array, "... 3"]) -> Float[Array, "... 3"]:
    """``R(q) v = (w² - u·u) v + 2 (u·v) u + 2 w (u × v)`` with ``q = (w, u)``.

    Exact rotation for unit ``q``; for other ``q`` it is the same quadratic form, scaled
    by ``|q|²``.
    """
    w = q[..., :1]
    u = q[..., 1:]
    uu = jnp.sum(u * u, axis=-1, keepdims=True)
    uv = jnp.sum(u * v, axis=-1, keepdims=True)
    return (w * w - uu) * v + 2.0 * uv * u + 2.0 * w * jnp.cross(u, v)


def multiply(
    p: Float[Array, "... 4"], q: Float[Array, "... 4"]
) -> Float[Array, "... 4"]:
    """Hamilton product ``p ⊗ q``."""
    pw, pv = p[..., :1], p[..., 1:]
    qw, qv = q[..., :1], q[..., 1:]
    w = pw * qw - jnp.sum(pv * qv, axis=-1, keepdims=True)
    v = pw * qv + qw * pv + jnp.cross(pv, qv)
    return jnp.concatenate([w, v], axis=-1)


def conjugate(q: Float[Array, "... 4"]) -> Float[Array, "... 4"]:
    """Conjugate ``(w, -x, -y, -z)``; the inverse rotation for unit ``q``."""
    return q * jnp.array([1.0, -1.0, -1.0, -1.0])


def from_axis_angle(
    axis: Float[Array, "... 3"], angle: Float[Array, ...]
) -> Float[Array, "... 4"]:
    """Unit quaternion of a rotation by ``angle`` (rad) about the unit vector
    ``axis``."""
    half = 0.5 * jnp.asarray(angle)[..., None]
    return jnp.concatenate([jnp.cos(half), jnp.sin(half) * axis], axis=-1)
