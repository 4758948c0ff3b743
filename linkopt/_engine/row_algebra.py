"""The local algebra of the constraint rows' Jacobian blocks (:mod:`.jacobian`): static
gathers, unrolled short dot products and sums, the derivatives of a rotated vector and
of a dot product with one in the quaternion, row blocks, the frames of a group of
joints, and the rows laid out for the normal equations (two bodies wide, or summed
block by block). Everything is plain ``jax.numpy`` without scatters, jit/vmap
friendly and differentiable again."""

from __future__ import annotations

from dataclasses import dataclass

import jax.numpy as jnp
import numpy as np
from jaxtyping import Array

from .. import _config  # noqa: F401  (float64 on before any array)
from .geometry import Geometry
from .model import Mechanism


def take(a, index: np.ndarray):
    """``a[index]`` along axis 0 for a static index: a slice where the index is a
    run, else one gather with constant indices. A gather is one operation however
    many members a group has, where a stack of one slice per member grew the programs
    with the joints (on the Stewart platform's evaluation, stacks were a tenth of the
    operations); ``benchmarks/bench_compile.py`` measures the compile times."""
    index = np.asarray(index, dtype=int)
    if index.size and np.array_equal(index, np.arange(index[0], index[0] + index.size)):
        return a[int(index[0]) : int(index[0]) + index.size]
    return a[index]


def dot(a, b):
    """Dot product over a short last axis, unrolled: reductions would end XLA
    fusions."""
    out = a[..., 0] * b[..., 0]
    for k in range(1, a.shape[-1]):
        out = out + a[..., k] * b[..., k]
    return out


def sum_rows(a):
    """Sum over axis 1 (the rows of a group), unrolled."""
    out = a[:, 0]
    for k in range(1, a.shape[1]):
        out = out + a[:, k]
    return out


def gram(a, b):
    """``Σ_k a[:, k]ᵀ b[:, k]`` for blocks ``(G, m, 7)``: ``(G, 7, 7)``, row by row."""
    out = a[:, 0, :, None] * b[:, 0, None, :]
    for k in range(1, a.shape[1]):
        out = out + a[:, k, :, None] * b[:, k, None, :]
    return out


def rotate_grad(q, v):
    """``∂(R(q) v)/∂q``, shape ``(..., 3, 4)``."""
    w, u = q[..., :1], q[..., 1:]
    dw = 2.0 * (w * v + jnp.cross(u, v))
    uv = dot(u, v)[..., None, None]
    eye = jnp.eye(3)
    ekv = jnp.swapaxes(jnp.cross(eye, v[..., None, :]), -1, -2)  # column k: e_k x v
    du = 2.0 * (
        uv * eye
        + u[..., :, None] * v[..., None, :]
        - v[..., :, None] * u[..., None, :]
        + w[..., None] * ekv
    )
    return jnp.concatenate([dw[..., :, None], du], axis=-1)


def dot_grad(q, v, a):
    """``∂(a · R(q) v)/∂q`` for ``a`` held fixed, shape ``(..., 4)``."""
    w, u = q[..., :1], q[..., 1:]
    av = dot(a, v)[..., None]
    dw = 2.0 * (w * av + dot(a, jnp.cross(u, v))[..., None])
    du = 2.0 * (
        -av * u
        + dot(u, a)[..., None] * v
        + dot(u, v)[..., None] * a
        + w * jnp.cross(v, a)
    )
    return jnp.concatenate([dw, du], axis=-1)


def q_block(dq):
    """A row block touching only the quaternion: ``(..., 4)`` -> ``(..., 7)``."""
    return jnp.concatenate([jnp.zeros(dq.shape[:-1] + (3,)), dq], axis=-1)


def xq_block(dx, dq):
    return jnp.concatenate([dx, dq], axis=-1)


def stack_rows(*rows):
    """Stack ``(value, jac_i, jac_j)`` rows into ``values (G, m)``, two ``(G, m, 7)``
    blocks."""
    values = jnp.stack([r[0] for r in rows], axis=1)
    ji = jnp.stack([r[1] for r in rows], axis=1)
    jj = jnp.stack([r[2] for r in rows], axis=1)
    return values, ji, jj


@dataclass(frozen=True)
class Frames:
    xi: Array
    qi: Array
    ri: Array
    xj: Array
    qj: Array
    rj: Array
    n: Array
    u: Array
    n2: Array


def frames(mech: Mechanism, geom: Geometry, x, q, index: np.ndarray) -> Frames:
    bi, bj = mech.joint_bodies[index, 0], mech.joint_bodies[index, 1]
    anchor = take(geom.anchors, index)
    return Frames(
        take(x, bi),
        take(q, bi),
        anchor - take(geom.origins, bi),
        take(x, bj),
        take(q, bj),
        anchor - take(geom.origins, bj),
        take(geom.axes, index),
        take(geom.helpers, index),
        take(geom.axes2, index),
    )


def two_body_layout(groups: list):
    """The rows of ``groups`` (each with values ``(G, m)`` and one or two blocks
    ``(bodies (G,), jac (G, m, 7))``) as ``(values (m,), rows (m, 14), pairs (m, 2))``:
    each row's two ``7``-blocks side by side and their static bodies (``-1`` and a
    zero block for a row on one body), for :func:`.dense.block_normal`."""
    values, rows, pairs = [], [], []
    for group in groups:
        count, m = group.values.shape
        values.append(group.values.reshape(-1))
        (first, block), *rest = group.blocks
        second, other = rest[0] if rest else (np.full(count, -1), jnp.zeros_like(block))
        rows.append(jnp.concatenate([block, other], axis=-1).reshape(count * m, 14))
        pairs.append(np.repeat(np.stack([first, second], axis=1), m, axis=0))
    return jnp.concatenate(values), jnp.concatenate(rows), np.concatenate(pairs)


def block_sums(groups: list, nb: int):
    """``(JᵀJ, JᵀC)`` of ``groups`` summed from ``7 x 7`` body blocks in plain JAX
    (the path without the compiled kernels)."""
    hess: dict[tuple[int, int], list] = {}
    grad: dict[int, list] = {}
    for group in groups:
        r = group.values
        for a, (bodies_a, jac_a) in enumerate(group.blocks):
            ga = sum_rows(jac_a * r[:, :, None])  # (G, 7)
            for k, b in enumerate(bodies_a):
                grad.setdefault(int(b), []).append(ga[k])
            for bodies_b, jac_b in group.blocks[a:]:
                prod = gram(jac_a, jac_b)  # (G, 7, 7)
                same = jac_b is jac_a
                for k in range(len(bodies_a)):
                    i, j = int(bodies_a[k]), int(bodies_b[k])
                    hess.setdefault((i, j), []).append(prod[k])
                    if not same:
                        hess.setdefault((j, i), []).append(prod[k].T)
    zero = jnp.zeros((7, 7))
    blocks = [
        [
            sum(hess[(i, j)][1:], hess[(i, j)][0]) if (i, j) in hess else zero
            for j in range(nb)
        ]
        for i in range(nb)
    ]
    hessian = jnp.block(blocks)
    gradient = jnp.concatenate(
        [sum(grad[i][1:], grad[i][0]) if i in grad else jnp.zeros(7) for i in range(nb)]
    )
    return hessian, gradient
