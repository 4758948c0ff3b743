"""Residual and exact state Jacobian of ``C_FK`` / ``C_BK`` in one block-sparse pass.

Every row of the constraint system touches at most two bodies (14 of the ``7B`` state
entries), so instead of ``jax.jacfwd`` over the whole state (``7B`` tangent directions
through the full residual) each row group is differentiated analytically in its local
variables. The rows are polynomial in the state (see :mod:`linkopt._engine.joints`), so
with ``R(q) v`` the quadratic form of :func:`linkopt._engine.rotations.rotate`

* ``∂(R(q) v)/∂q = 2 [w v + u × v,  (u·v) I + u vᵀ - v uᵀ - w [v]×]``
  for ``q = (w, u)``;
* ``∂(a · R(q) v)/∂q =
  2 (w (a·v) + a·(u × v),  -(a·v) u + (u·a) v + (u·v) a + w (v × a))``;
* a wrapped angle ``atan2(s, c)`` (any target) has the gradient
  ``(c ∇s - s ∇c) / (c² + s²)``.

A row group is a :class:`_Rows`: its values ``(G, m)`` and, per touched body, the static
body index of each of its ``G`` members and the ``(G, m, 7)`` block of the Jacobian.
From these come the dense Jacobian (:func:`linearise`, :func:`state_jacobian`,
:func:`stacked_jacobians`) or, for Levenberg–Marquardt, directly the normal equations
``JᵀJ`` and ``Jᵀr`` assembled from ``7 x 7`` body blocks (:func:`normal_equations`),
never forming the mostly-zero dense ``J``: the rows' blocks laid out two bodies wide
and summed in one call of the compiled kernel (:func:`.dense.block_normal`) where it is
built, else block by block in plain JAX. Everything else is plain ``jax.numpy``
without scatters (static indices become slices or gathers with constant indices), so
it is jit/vmap friendly and differentiable again in the state and the geometry
(``f_sing`` needs ``∂J/∂s``, ``∂J/∂p``).

The row order and values are those of :func:`linkopt._engine.constraints.fk_residual` /
``bk_residual`` (same formulas, so equal up to rounding), and the Jacobians equal
``jax.jacfwd`` of those to rounding (``tests`` compare them to 1e-12).

The entry points that the samplers call many times (``state_jacobian``,
``stacked_jacobians``, ``normal_equations``) are jitted with the mechanism (and
``kind``) static, so one evaluation traces each once and reuses the jaxpr at every other
call site.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import partial

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from .._config import jit
from . import dense
from . import joints as joint_types
from .constraints import gauge_rows
from .geometry import Geometry
from .model import JOINT_ROWS, Mechanism
from .row_algebra import (
    Frames,
    block_sums,
    dot,
    frames,
    q_block,
    stack_rows,
    take,
    two_body_layout,
    xq_block,
)
from .turns import Side, Turn, body_turns, take_turn


@dataclass(frozen=True)
class _Rows:
    values: Float[Array, "G m"]
    blocks: tuple  # ((bodies: np.ndarray (G,), jac: (G, m, 7)), ...)


def _point_rows(f: Frames, si: Side, sj: Side):
    """The 3 point-coincidence rows ``d`` and their blocks ``(G, 3, 7)``, plus ``d``."""
    d = (f.xj + sj.rot(f.rj)) - (f.xi + si.rot(f.ri))
    eye = jnp.broadcast_to(jnp.eye(3), d.shape[:-1] + (3, 3))
    ji = jnp.concatenate([-eye, -si.slope(f.ri)], axis=-1)
    jj = jnp.concatenate([eye, sj.slope(f.rj)], axis=-1)
    return d, ji, jj


def _pair_row(si: Side, vi, sj: Side, vj):
    """Row ``(R_i vi)·(R_j vj)`` with its two blocks."""
    a, b = si.rot(vi), sj.rot(vj)
    return dot(a, b), q_block(si.dot_grad(vi, b)), q_block(sj.dot_grad(vj, a))


def _slide_row(f: Frames, si: Side, sj: Side, d, v):
    """Row ``d · (R_i v)`` with ``d`` the anchor separation, with its two blocks."""
    e = si.rot(v)
    ji = xq_block(-e, si.dot_grad(v, d) - si.dot_grad(f.ri, e))
    jj = xq_block(e, sj.dot_grad(f.rj, e))
    return dot(d, e), ji, jj


def _angle_row(si: Side, sj: Side, n, u, target):
    """Wrapped ``relative_angle - target`` (or the angle when ``target`` is None) and
    blocks."""
    w = jnp.cross(n, u)
    uj = sj.rot(u)
    ui, wi = si.rot(u), si.rot(w)
    c, s = dot(uj, ui), dot(uj, wi)
    if target is None:
        value = jnp.arctan2(s, c)
    else:
        ct, st = jnp.cos(target), jnp.sin(target)
        value = jnp.arctan2(s * ct - c * st, c * ct + s * st)
    scale = 1.0 / (c * c + s * s)
    cs, ss = (c * scale)[..., None], (s * scale)[..., None]
    dqi = cs * si.dot_grad(w, uj) - ss * si.dot_grad(u, uj)
    dqj = cs * sj.dot_grad(u, wi) - ss * sj.dot_grad(u, ui)
    return value, q_block(dqi), q_block(dqj)


def _sides(mech: Mechanism, turns: Turn, joints: np.ndarray) -> tuple[Side, Side]:
    """The two sides of the joints ``joints`` (static)."""
    bodies = mech.joint_bodies[joints]
    return Side(take_turn(turns, bodies[:, 0])), Side(take_turn(turns, bodies[:, 1]))


def _family_rows(kind: str, f: Frames, si: Side, sj: Side):
    """Rows ``(G, m)`` and blocks ``(G, m, 7)`` of one joint family, row order of
    ``_joints``."""
    w = jnp.cross(f.n, f.u)
    parts = []  # each: (values (G, k), ji (G, k, 7), jj (G, k, 7))
    d = None
    if kind in (
        "revolute",
        "spherical",
        "universal",
        "fixed",
        "prismatic",
        "cylindrical",
    ):
        d, di, dj = _point_rows(f, si, sj)
        if kind in ("revolute", "spherical", "universal", "fixed"):
            parts.append((d, di, dj))
    if kind in ("revolute", "prismatic", "cylindrical", "fixed"):
        parts.append(stack_rows(_pair_row(si, f.n, sj, f.u), _pair_row(si, f.n, sj, w)))
    if kind == "universal":
        parts.append(stack_rows(_pair_row(si, f.n, sj, f.n2)))
    if kind in ("prismatic", "fixed"):
        parts.append(stack_rows(_pair_row(si, f.u, sj, w)))
    if kind in ("prismatic", "cylindrical"):
        parts.append(
            stack_rows(_slide_row(f, si, sj, d, f.u), _slide_row(f, si, sj, d, w))
        )
    values = jnp.concatenate([p[0] for p in parts], axis=1)
    ji = jnp.concatenate([p[1] for p in parts], axis=1)
    jj = jnp.concatenate([p[2] for p in parts], axis=1)
    return values, ji, jj


# ---------------------------------------------------------------------------------
# Row groups of C_FK / C_BK.


def _passive_groups(mech: Mechanism, geom: Geometry, x, q, turns) -> list[_Rows]:
    bodies = np.arange(mech.num_bodies)
    groups = [
        _Rows(dot(q, q)[:, None] - 1.0, ((bodies, q_block(2.0 * q)[:, None, :]),))
    ]
    g = mech.ground
    ground = jnp.concatenate([x[g] - geom.origins[g], q[g, 1:]])
    pin = np.zeros((6, 7))
    pin[:3, :3] = np.eye(3)
    pin[3:, 4:] = np.eye(3)
    groups.append(_Rows(ground[None], ((np.array([g]), jnp.asarray(pin)[None]),)))
    for kind in JOINT_ROWS:
        index = mech.joints_of(kind)
        if index.size:
            f = frames(mech, geom, x, q, index)
            values, ji, jj = _family_rows(kind, f, *_sides(mech, turns, index))
            groups.append(
                _Rows(
                    values,
                    (
                        (mech.joint_bodies[index, 0], ji),
                        (mech.joint_bodies[index, 1], jj),
                    ),
                )
            )
    if mech.idle_bodies.size:  # gauge rows of idle spins (constraints.gauge_rows)
        values, dq = gauge_rows(mech, geom, q)
        block = q_block(dq)[:, None, :]
        groups.append(_Rows(values[:, None], ((mech.idle_bodies, block),)))
    return groups


def _joint_rows(mech: Mechanism, joints: np.ndarray, value, ji, jj) -> _Rows:
    """One row per joint of ``joints`` (values ``(G,)``, blocks ``(G, 7)`` on each
    joint's two bodies)."""
    return _Rows(
        value[:, None],
        (
            (mech.joint_bodies[joints, 0], ji[:, None]),
            (mech.joint_bodies[joints, 1], jj[:, None]),
        ),
    )


def _motor_groups(mech: Mechanism, geom: Geometry, x, q, turns, motors):
    """Motor rows (values, or errors against ``motors``) and their raw row order."""
    groups, order = [], []
    rotary = np.flatnonzero(~mech.motor_linear)
    linear = np.flatnonzero(mech.motor_linear)
    for index, is_linear in ((rotary, False), (linear, True)):
        if not index.size:
            continue
        joints = mech.motor_joints[index]
        f = frames(mech, geom, x, q, joints)
        si, sj = _sides(mech, turns, joints)
        target = None if motors is None else take(motors, index)
        if is_linear:
            d = (f.xj + sj.rot(f.rj)) - (f.xi + si.rot(f.ri))
            value, ji, jj = _slide_row(f, si, sj, d, f.n)
            if target is not None:
                value = value - target
        else:
            value, ji, jj = _angle_row(si, sj, f.n, f.u, target)
        groups.append(_joint_rows(mech, joints, value, ji, jj))
        order.append(index)
    return groups, order


def _output_groups(mech: Mechanism, geom: Geometry, x, q, turns, outputs):
    """Output rows (values, or errors against ``outputs``) and their raw row order."""
    groups, order = _orientation_groups(mech, geom, x, q, turns, outputs)
    positional = np.flatnonzero(mech.output_points >= 0)
    angle = np.array(mech.output_kinds, dtype=object) == "angle"
    angular = np.flatnonzero(angle & (mech.output_coords < 0))
    tait_bryan = np.flatnonzero(angle & (mech.output_coords >= 0))
    if positional.size:
        points = mech.output_points[positional]
        coords = mech.output_coords[positional]
        body = mech.point_bodies[points]
        side = Side(take_turn(turns, body))
        r = take(geom.points, points) - take(geom.origins, body)
        select = jnp.asarray(np.eye(3)[coords])  # (G, 3) one-hot coordinate
        world = take(x, body) + side.rot(r)
        value = jnp.stack([world[k, int(c)] for k, c in enumerate(coords)])
        if outputs is not None:
            value = value - take(outputs, positional)
        block = xq_block(select, side.dot_grad(r, select))
        groups.append(_Rows(value[:, None], ((body, block[:, None]),)))
        order.append(positional)
    if angular.size:
        joints = mech.output_joints[angular]
        f = frames(mech, geom, x, q, joints)
        target = None if outputs is None else take(outputs, angular)
        value, ji, jj = _angle_row(*_sides(mech, turns, joints), f.n, f.u, target)
        groups.append(_joint_rows(mech, joints, value, ji, jj))
        order.append(angular)
    if tait_bryan.size:
        joints = mech.output_joints[tait_bryan]
        f = frames(mech, geom, x, q, joints)
        target = None if outputs is None else take(outputs, tait_bryan)
        value, ji, jj = _tait_bryan_row(
            f.qi, f.qj, f.n, f.n2, mech.output_coords[tait_bryan], target
        )
        groups.append(_joint_rows(mech, joints, value, ji, jj))
        order.append(tait_bryan)
    return groups, order


def _orientation_groups(mech: Mechanism, geom: Geometry, x, q, turns, outputs):
    """Orientation, direction and displacement output rows (see ``_output_groups``):
    the Tait–Bryan angles of one body relative to another in a fixed frame, the tilt
    of a body's axis, and the slide of a prismatic/cylindrical joint (the linear
    motor's row)."""
    groups, order = [], []
    table = mech.output_table
    turned, slid = table.of("orientation"), table.of("displacement")
    pointed = table.of("direction")
    if pointed.size:
        pair = table.bodies[pointed]
        frame = jnp.asarray(table.frames[pointed])
        target = None if outputs is None else take(outputs, pointed)
        value, ji, jj = _local_row(
            joint_types.direction_angles,
            take(q, pair[:, 0]),
            take(q, pair[:, 1]),
            frame[:, 0],
            frame[:, 1],
            table.coords[pointed],
            target,
        )
        blocks = ((pair[:, 0], ji[:, None]), (pair[:, 1], jj[:, None]))
        groups.append(_Rows(value[:, None], blocks))
        order.append(pointed)
    if turned.size:
        pair = table.bodies[turned]
        frame = jnp.asarray(table.frames[turned])
        target = None if outputs is None else take(outputs, turned)
        value, ji, jj = _tait_bryan_row(
            take(q, pair[:, 0]),
            take(q, pair[:, 1]),
            frame[:, 0],
            frame[:, 1],
            table.coords[turned],
            target,
        )
        blocks = ((pair[:, 0], ji[:, None]), (pair[:, 1], jj[:, None]))
        groups.append(_Rows(value[:, None], blocks))
        order.append(turned)
    if slid.size:
        joints = table.joints[slid]
        f = frames(mech, geom, x, q, joints)
        si, sj = _sides(mech, turns, joints)
        d = (f.xj + sj.rot(f.rj)) - (f.xi + si.rot(f.ri))
        value, ji, jj = _slide_row(f, si, sj, d, f.n)
        if outputs is not None:
            value = value - take(outputs, slid)
        bodies = mech.joint_bodies[joints]
        blocks = ((bodies[:, 0], ji[:, None]), (bodies[:, 1], jj[:, None]))
        groups.append(_Rows(value[:, None], blocks))
        order.append(slid)
    return groups, order


def _tait_bryan_row(qi, qj, e1, e2, which: np.ndarray, target):
    """One Tait–Bryan angle per member (``which``: static 0..2), wrapped against
    ``target`` (:func:`_local_row` of :func:`linkopt._engine.joints.tait_bryan`: its
    three nested ``atan2`` have no short closed form worth keeping)."""
    return _local_row(joint_types.tait_bryan, qi, qj, e1, e2, which, target)


def _local_row(angles, qi, qj, e1, e2, which: np.ndarray, target):
    """Angle ``which[g]`` (static) of ``angles(q_i, q_j, e1, e2)`` per member, wrapped
    against ``target``, differentiated by forward mode in the 8 local quaternion
    entries."""
    select = jnp.asarray(np.eye(3)[which])  # (G, 3) one-hot

    def angle(a, b, n, n2, pick, goal):
        every = angles(a, b, n, n2)
        value = dot(every, pick[: every.shape[0]])
        return value if goal is None else joint_types.wrap(value - goal)

    def local(a, b, n, n2, pick, goal):
        value = angle(a, b, n, n2, pick, goal)
        da, db = jax.jacfwd(angle, argnums=(0, 1))(a, b, n, n2, pick, goal)
        return value, da, db

    value, dqi, dqj = jax.vmap(local)(
        qi, qj, e1, e2, select, target
    )  # target None: no leaves
    return value, q_block(dqi), q_block(dqj)


def _split(state, unrolled: bool = False):
    """Positions ``(B, 3)``, quaternions ``(B, 4)`` and :class:`Turn` of the bodies
    (``unrolled``: :attr:`.turns.Turn.unrolled`, for the solves' linearisations)."""
    bodies = state.reshape(-1, 7)
    return bodies[:, :3], bodies[:, 3:], body_turns(bodies[:, 3:], unrolled)


def _tail_groups(mech: Mechanism, geom: Geometry, kind: str, x, q, turns, values):
    if kind == "fk":
        return _motor_groups(mech, geom, x, q, turns, values)
    if kind == "bk":
        return _output_groups(mech, geom, x, q, turns, values)
    raise ValueError(f"kind must be 'fk' or 'bk', not {kind!r}")


def row_groups(mech: Mechanism, geom: Geometry, kind: str, values, state):
    """``(passive, tail, order)``: the row groups of ``C_FK``/``C_BK`` (each with
    ``values (G, m)`` and ``blocks``, ``((bodies (G,), jac (G, m, 7)), ...)``) and the
    raw order of the tail rows, for assemblies outside this module
    (:mod:`linkopt._engine.banded`)."""
    x, q, t = _split(state)
    tail, order = _tail_groups(mech, geom, kind, x, q, t, values)
    return _passive_groups(mech, geom, x, q, t), tail, order


# ---------------------------------------------------------------------------------
# Dense assembly.


def _dense(groups: list[_Rows], num_bodies: int):
    """Concatenated values ``(m,)`` and dense Jacobian ``(m, 7B)`` of row groups."""
    values, rows = [], []
    for group in groups:
        count, m = group.values.shape
        values.append(group.values.reshape(-1))
        out = jnp.zeros((count, m, num_bodies, 7))
        for bodies, jac in group.blocks:
            onehot = jnp.asarray(np.eye(num_bodies, dtype=bool)[bodies])[
                :, None, :, None
            ]
            out = out + jnp.where(onehot, jac[:, :, None, :], 0.0)
        rows.append(out.reshape(count * m, 7 * num_bodies))
    return jnp.concatenate(values), jnp.concatenate(rows, axis=0)


def _permute_tail(residual, jacobian, head: int, order: list[np.ndarray]):
    """Put the tail rows (raw order ``concat(order)``) into motor/output index order."""
    if not order:
        return residual, jacobian
    perm = np.argsort(np.concatenate(order), kind="stable")
    if np.array_equal(perm, np.arange(perm.size)):
        return residual, jacobian
    index = np.concatenate([np.arange(head), head + perm])
    return take(residual, index), take(jacobian, index)


def linearise(
    mech: Mechanism, geom: Geometry, kind: str, values, state: Float[Array, " S"]
):
    """``(C, ∂C/∂s)`` of ``C_FK`` (``kind="fk"``, ``values`` the motors) or ``C_BK``
    (``"bk"``, the outputs), homogenised, equal to ``fk_residual``/``bk_residual`` and
    ``jax.jacfwd`` of it. ``values=None`` gives the motor/output values instead of
    errors in the last rows (the Jacobian does not depend on the targets)."""
    x, q, t = _split(state)
    passive = _passive_groups(mech, geom, x, q, t)
    tail, order = _tail_groups(mech, geom, kind, x, q, t, values)
    residual, jacobian = _dense(passive + tail, mech.num_bodies)
    head = sum(int(np.prod(g.values.shape)) for g in passive)
    return _permute_tail(residual, jacobian, head, order)


@partial(jit, static_argnums=2)
def state_jacobian(
    mech: Mechanism, geom: Geometry, kind: str, state: Float[Array, " S"]
) -> Float[Array, "m S"]:
    """``∂C_FK/∂s`` (``kind="fk"``) or ``∂C_BK/∂s`` (``"bk"``) at ``state``; targets
    play no part."""
    return linearise(mech, geom, kind, None, state)[1]


@jit
def stacked_jacobians(
    mech: Mechanism, geom: Geometry, state: Float[Array, " S"]
) -> Float[Array, "2 m S"]:
    """``[∂C_FK/∂s, ∂C_BK/∂s]``, the passive rows computed once (as in
    ``_singularity``)."""
    x, q, t = _split(state)
    _, passive = _dense(_passive_groups(mech, geom, x, q, t), mech.num_bodies)
    out = []
    for kind in ("fk", "bk"):
        tail, order = _tail_groups(mech, geom, kind, x, q, t, None)
        values, rows = _dense(tail, mech.num_bodies)
        _, rows = _permute_tail(values, rows, 0, order)
        out.append(jnp.concatenate([passive, rows]))
    return jnp.stack(out)


# ---------------------------------------------------------------------------------
# Normal equations for Levenberg–Marquardt.


@partial(jit, static_argnums=2)
def normal_equations(
    mech: Mechanism, geom: Geometry, kind: str, values, state: Float[Array, " S"]
):
    """``(C, JᵀJ, JᵀC)`` with ``J = ∂C/∂s``, assembled from ``7 x 7`` body blocks.

    ``C`` is in the row order of ``fk_residual``/``bk_residual``; ``JᵀJ`` and ``JᵀC``
    equal the dense products up to rounding (summation order differs).
    """
    return normal_system(mech, geom, kind, values, state)


@partial(jit, static_argnums=2)
def normal_equations_tail(
    mech: Mechanism, geom: Geometry, kind: str, values, state: Float[Array, " S"]
):
    """``(C, JᵀJ, JᵀC, J_tail)``: :func:`normal_equations` and the Jacobian of the
    motor (``kind="fk"``) or output (``"bk"``) rows, ``(k, S)`` in index order, the
    last rows of :func:`linearise`'s (what a continuation's next prediction needs,
    :func:`.continuation.predict_from`)."""
    return normal_system(mech, geom, kind, values, state, with_tail=True)


def normal_system(
    mech: Mechanism,
    geom: Geometry,
    kind: str,
    values,
    state: Float[Array, " S"],
    with_tail: bool = False,
):
    """:func:`normal_equations` traced in place (not a program of its own). The rows'
    ``7``-blocks are laid out two bodies wide (:func:`.row_algebra.two_body_layout`)
    and assembled in one call of the compiled kernel (:func:`.dense.block_normal`),
    where it serves them; else summed block by block in plain JAX
    (:func:`.row_algebra.block_sums`)."""
    x, q, t = _split(state, unrolled=True)
    groups = _passive_groups(mech, geom, x, q, t)
    tail, order = _tail_groups(mech, geom, kind, x, q, t, values)
    groups = groups + tail
    nb = mech.num_bodies
    residual, rows, pairs = two_body_layout(groups)
    if dense.serves_block_normal(rows, 7 * nb):
        hessian, gradient = dense.block_normal(rows, residual, pairs, 7 * nb)
    else:
        hessian, gradient = block_sums(groups, nb)
    head = sum(int(np.prod(g.values.shape)) for g in groups[: len(groups) - len(tail)])
    perm = np.argsort(np.concatenate(order), kind="stable") if order else np.arange(0)
    if not np.array_equal(perm, np.arange(perm.size)):
        residual = take(residual, np.concatenate([np.arange(head), head + perm]))
    if not with_tail:
        return residual, hessian, gradient
    rows, pairs = take(rows, head + perm), pairs[head + perm]
    return residual, hessian, gradient, dense.rows_matrix(rows, pairs, 7 * nb)
