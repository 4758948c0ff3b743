"""Assembly of the constraint vectors ``C_FK(a, s)`` and ``C_BK(b, s)`` (paper Sec. II).

Row order (static for a mechanism): one unit-norm row per body quaternion, six rows
pinning the ground (origin and quaternion vector part), the passive rows of every joint
grouped by family in :data:`linkopt._engine.model.JOINT_ROWS` order, one gauge row per
idle spin (:func:`gauge_rows`), then one row per motor (FK) or per output (BK).
Backward kinematics keeps every motor's joint as a passive joint and swaps the motor
rows for output rows, so with as many motors as outputs both Jacobians have the same
shape. All inputs are homogenised.

The entry points that the samplers call many times (``fk_residual``,
``output_residual``, ``homogenised_output_values``) are jitted with the mechanism (and
``kind``) static, so one evaluation traces each once and reuses the jaxpr at every
other call site.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from .._config import jit
from . import joints as joint_types
from .geometry import Geometry
from .model import JOINT_ROWS, Mechanism
from .rotations import rotate


def body_frames(
    state: Float[Array, " S"],
) -> tuple[Float[Array, "B 3"], Float[Array, "B 4"]]:
    bodies = state.reshape(-1, 7)
    return bodies[:, :3], bodies[:, 3:]


def _joint_frames(mech: Mechanism, geom: Geometry, state, index: np.ndarray):
    """Per-joint arguments ``(x_i, q_i, r_i, x_j, q_j, r_j, n, u, n2)`` for joints
    ``index``."""
    x, q = body_frames(state)
    bi, bj = mech.joint_bodies[index, 0], mech.joint_bodies[index, 1]
    anchor = geom.anchors[index]
    return (
        x[bi],
        q[bi],
        anchor - geom.origins[bi],
        x[bj],
        q[bj],
        anchor - geom.origins[bj],
        geom.axes[index],
        geom.helpers[index],
        geom.axes2[index],
    )


def passive_residual(
    mech: Mechanism, geom: Geometry, state: Float[Array, " S"]
) -> Float[Array, " R"]:
    """Quaternion norms, ground pin and every joint's passive rows (no motors, no
    outputs)."""
    x, q = body_frames(state)
    rows = [
        jnp.sum(q * q, axis=1) - 1.0,
        x[mech.ground] - geom.origins[mech.ground],
        q[mech.ground, 1:],
    ]
    for kind in JOINT_ROWS:
        index = mech.joints_of(kind)
        if index.size:
            family = jax.vmap(joint_types.FAMILIES[kind])
            rows.append(family(*_joint_frames(mech, geom, state, index)).ravel())
    if mech.idle_bodies.size:
        rows.append(gauge_rows(mech, geom, q)[0])
    return jnp.concatenate(rows)


def idle_axes(mech: Mechanism, geom: Geometry) -> Float[Array, "I 3"]:
    """Unit axis ``d`` of each idle body, body-local (= world at rest), from its first
    to its second ball joint; it follows the design's anchors."""
    start = jnp.stack([geom.anchors[int(k)] for k in mech.idle_joints[:, 0]])
    end = jnp.stack([geom.anchors[int(k)] for k in mech.idle_joints[:, 1]])
    d = end - start
    return d / jnp.sqrt(jnp.sum(d * d, axis=1, keepdims=True))


def gauge_rows(
    mech: Mechanism, geom: Geometry, q: Float[Array, "B 4"]
) -> tuple[Float[Array, " I"], Float[Array, "I 4"]]:
    """The gauge row ``2 v·d`` of each idle body (``q = (w, v)`` its quaternion, ``d``
    its :func:`idle_axes`) and its gradient ``(0, 2d)`` in ``q``.

    Write ``q = q_swing ⊗ q_twist`` with the twist ``(c, t d)`` about the body-local
    axis and the swing ``(a, s)``, ``s ⟂ d``: then ``v·d = a t``, so the row is zero
    exactly when the twist is (for a swing under 180°, ``a ≠ 0``): it picks the
    spin-free pose of the rod and leaves its direction, the only thing the two ball
    joints see, free. It is polynomial in ``q`` (smooth everywhere, no normalisation).
    A spin ``ε`` about ``d`` changes it by ``w ε`` to first order (``(v × d)·d = 0``),
    while the ball joints' rows do not change at all: the row is independent of them
    wherever ``w ≠ 0``, i.e. while the rod is turned less than 180° from its rest
    direction, the limit of this gauge (past it, ``w → 0`` and the row stops fixing
    the spin). The factor 2 gives it unit slope per radian of spin at rest, like the
    angle rows of the other joints, so the homogenised σ_min stays on one scale.
    """
    d = idle_axes(mech, geom)
    vector = jnp.stack([q[int(b), 1:] for b in mech.idle_bodies])
    gradient = jnp.concatenate([jnp.zeros((d.shape[0], 1)), 2.0 * d], axis=1)
    return 2.0 * jnp.sum(vector * d, axis=1), gradient


def _combine(size: int, parts) -> Float[Array, " K"]:
    """Place each ``(static index, values)`` part into a vector of length ``size``.

    Each family is evaluated only on its own entries, so no branch that is masked out
    (an angle at a joint without an axis, say) can leak a NaN into a gradient.
    """
    out = jnp.zeros((size,))
    for index, values in parts:
        if index.size:
            out = out.at[index].set(values(index))
    return out


def _joint_angles(mech: Mechanism, geom: Geometry, state, joints, targets, index):
    """The relative angles at ``joints`` (``targets`` None), or their wrapped errors
    against ``targets[index]``."""
    _, qi, _, _, qj, _, n, u, _ = _joint_frames(mech, geom, state, joints)
    if targets is None:
        return jax.vmap(joint_types.relative_angle)(qi, qj, n, u)
    return jax.vmap(joint_types.angle_error)(qi, qj, n, u, targets[index])


def _motor_rows(mech: Mechanism, geom: Geometry, state, motors):
    linear = np.flatnonzero(mech.motor_linear)
    rotary = np.flatnonzero(~mech.motor_linear)

    def angles(index):
        return _joint_angles(mech, geom, state, mech.motor_joints[index], motors, index)

    def shifts(index):
        xi, qi, ri, xj, qj, rj, n, _, _ = _joint_frames(
            mech, geom, state, mech.motor_joints[index]
        )
        value = jax.vmap(joint_types.slide)(xi, qi, ri, xj, qj, rj, n)
        return value if motors is None else value - motors[index]

    return _combine(mech.num_motors, [(rotary, angles), (linear, shifts)])


def homogenised_motor_values(
    mech: Mechanism, geom: Geometry, state: Float[Array, " S"]
) -> Float[Array, " M"]:
    """Motor values read off a state (homogenised; rad for revolute motors)."""
    return _motor_rows(mech, geom, state, None)


def motor_residual(
    mech: Mechanism, geom: Geometry, motors, state
) -> Float[Array, " M"]:
    """One row per motor: wrapped angle error (revolute) or slide error (linear)."""
    return _motor_rows(mech, geom, state, motors)


def _point_world(mech: Mechanism, geom: Geometry, state) -> Float[Array, "P 3"]:
    x, q = body_frames(state)
    body = mech.point_bodies
    return x[body] + rotate(q[body], geom.points - geom.origins[body])


def homogenised_point_positions(
    mech: Mechanism, geom: Geometry, state
) -> Float[Array, "P 3"]:
    """World positions of the named points (homogenised)."""
    return _point_world(mech, geom, state)


def homogenised_joint_positions(
    mech: Mechanism, geom: Geometry, state
) -> Float[Array, "J 3"]:
    """World position of each joint anchor, as seen from the joint's first body."""
    x, q = body_frames(state)
    body = mech.joint_bodies[:, 0]
    return x[body] + rotate(q[body], geom.anchors - geom.origins[body])


def _output_rows(mech: Mechanism, geom: Geometry, state, outputs, table=None):
    """Values (``outputs`` None) or wrapped errors of the outputs of ``table`` (the
    BK outputs unless given), homogenised, in table order."""
    table = mech.output_table if table is None else table
    kinds = np.array(table.kinds, dtype=object)
    angular = np.flatnonzero((kinds == "angle") & (table.coords < 0))
    tait_bryan = np.flatnonzero((kinds == "angle") & (table.coords >= 0))

    def coords(index):
        world = _point_world(mech, geom, state)[
            table.points[index], table.coords[index]
        ]
        return world if outputs is None else world - outputs[index]

    def angles(index):
        return _joint_angles(mech, geom, state, table.joints[index], outputs, index)

    def sequence(index):
        _, qi, _, _, qj, _, n, _, n2 = _joint_frames(
            mech, geom, state, table.joints[index]
        )
        return _pick_angle(qi, qj, n, n2, table.coords[index], outputs, index)

    def orientation(index):
        _, q = body_frames(state)
        pair, frame = table.bodies[index], jnp.asarray(table.frames[index])
        qi, qj = q[pair[:, 0]], q[pair[:, 1]]
        return _pick_angle(
            qi, qj, frame[:, 0], frame[:, 1], table.coords[index], outputs, index
        )

    def direction(index):
        _, q = body_frames(state)
        pair, frame = table.bodies[index], jnp.asarray(table.frames[index])
        every = jax.vmap(joint_types.direction_angles)(
            q[pair[:, 0]], q[pair[:, 1]], frame[:, 0], frame[:, 1]
        )
        value = jnp.stack([every[g, int(k)] for g, k in enumerate(table.coords[index])])
        return value if outputs is None else joint_types.wrap(value - outputs[index])

    def displacement(index):
        frames = _joint_frames(mech, geom, state, table.joints[index])
        value = jax.vmap(joint_types.slide)(*frames[:7])
        return value if outputs is None else value - outputs[index]

    return _combine(
        table.size,
        [
            (table.of("position"), coords),
            (angular, angles),
            (tait_bryan, sequence),
            (table.of("orientation"), orientation),
            (table.of("displacement"), displacement),
            (table.of("direction"), direction),
        ],
    )


def _pick_angle(qi, qj, e1, e2, which: np.ndarray, outputs, index):
    """Tait–Bryan angle ``which[g]`` (static 0..2) of ``q_j`` relative to ``q_i`` in
    the frame ``(e1, e2)`` per member (:func:`~.joints.tait_bryan`), or its wrapped
    error against ``outputs[index]``."""
    every = jax.vmap(joint_types.tait_bryan)(qi, qj, e1, e2)
    value = jnp.stack([every[g, int(k)] for g, k in enumerate(which)])
    return value if outputs is None else joint_types.wrap(value - outputs[index])


def reported_values(mech: Mechanism, geom: Geometry, state) -> Float[Array, " E"]:
    """Values of the reported outputs (homogenised; rad for angles)."""
    return _output_rows(mech, geom, state, None, mech.reported_table)


@jit
def homogenised_output_values(
    mech: Mechanism, geom: Geometry, state
) -> Float[Array, " K"]:
    """End-effector variables ``b(s)`` (homogenised; rad for angles)."""
    return _output_rows(mech, geom, state, None)


@jit
def output_residual(
    mech: Mechanism, geom: Geometry, outputs, state
) -> Float[Array, " K"]:
    """One row per output: ``b_k(s) - b_k``, angles wrapped to (-π, π]."""
    return _output_rows(mech, geom, state, outputs)


@jit
def fk_residual(mech: Mechanism, geom: Geometry, motors, state) -> Float[Array, " R"]:
    """``C_FK(a, s)``: passive rows then one row per motor."""
    return jnp.concatenate(
        [passive_residual(mech, geom, state), motor_residual(mech, geom, motors, state)]
    )


def bk_residual(mech: Mechanism, geom: Geometry, outputs, state) -> Float[Array, " R"]:
    """``C_BK(b, s)``: passive rows (motors as passive joints) then one row per
    output."""
    return jnp.concatenate(
        [
            passive_residual(mech, geom, state),
            output_residual(mech, geom, outputs, state),
        ]
    )


#: The residual of each solve kind, ``(mech, geom, values, state) -> C``.
RESIDUALS = {"fk": fk_residual, "bk": bk_residual}


def constraint_rows(mech: Mechanism) -> dict[str, int]:
    """Row counts of the passive part and of ``C_FK`` / ``C_BK``."""
    passive = mech.num_bodies + 6 + sum(JOINT_ROWS.get(t, 0) for t in mech.joint_types)
    passive += mech.idle_bodies.size  # one gauge row per idle spin
    return {
        "passive": passive,
        "fk": passive + mech.num_motors,
        "bk": passive + mech.num_outputs,
    }
