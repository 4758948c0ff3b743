"""Angle outputs of universal and spherical joints: Tait–Bryan angles about the joint's
axis, axis2 and axis × axis2, checked against rotations built from known angles."""

import jax
import jax.numpy as jnp
import numpy as np

from linkopt._engine import joints as _joints
from linkopt._engine.rotations import from_axis_angle, multiply


def _frame(rng):
    e1 = rng.normal(size=3)
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(e1, rng.normal(size=3))
    return e1, e2 / np.linalg.norm(e2)


def test_tait_bryan_recovers_the_angles_of_a_composed_rotation():
    rng = np.random.default_rng(0)
    for _ in range(20):
        e1, e2 = _frame(rng)
        e3 = np.cross(e1, e2)
        angles = rng.uniform(-1.4, 1.4, 3)
        qi = rng.normal(size=4)
        qi /= np.linalg.norm(qi)
        relative = multiply(
            multiply(from_axis_angle(e1, angles[0]), from_axis_angle(e2, angles[1])),
            from_axis_angle(e3, angles[2]),
        )
        qj = multiply(qi, relative)  # R_j = R_i Rot(e1) Rot(e2) Rot(e3)
        np.testing.assert_allclose(
            _joints.tait_bryan(qi, qj, jnp.asarray(e1), jnp.asarray(e2)),
            angles,
            atol=1e-12,
        )


def test_universal_joint_angles_are_its_two_rotations_and_the_third_is_zero():
    rng = np.random.default_rng(1)
    e1, e2 = _frame(rng)
    a, b = 0.7, -0.4
    qj = multiply(from_axis_angle(e1, a), from_axis_angle(e2, b))
    qi = jnp.array([1.0, 0.0, 0.0, 0.0])
    # the universal joint's own row: axis on body i stays perpendicular to axis2 on
    # body j
    row = _joints.universal(
        jnp.zeros(3), qi, jnp.zeros(3), jnp.zeros(3), qj, jnp.zeros(3), e1, e2, e2
    )[3]
    assert abs(row) < 1e-12
    np.testing.assert_allclose(
        _joints.tait_bryan(qi, qj, jnp.asarray(e1), jnp.asarray(e2)),
        [a, b, 0.0],
        atol=1e-12,
    )


def test_wrapped_error_is_smooth_across_pi():
    grad = jax.grad(lambda v: _joints.wrap(v - 3.1))
    assert abs(_joints.wrap(jnp.array(-3.1) - 3.1) - (2 * np.pi - 6.2)) < 1e-12
    np.testing.assert_allclose(grad(jnp.array(-3.1)), 1.0, atol=1e-12)
