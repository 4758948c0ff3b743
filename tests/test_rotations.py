"""The rotation module's group axioms and round trips, in the style of jaxlie's tests:
each property over generated quaternions, vectors and rotation vectors, small
(1e-7, 1e-13) rotations sampled on purpose, to 1e-12; the JAX half against the numpy
half; derivatives at the identity finite and equal to their closed forms."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from linkopt._engine import rotations as rot

TOL = 1e-12
IDENTITY = jnp.array([1.0, 0.0, 0.0, 0.0])

_coordinate = st.floats(-1.0, 1.0, allow_nan=False)
_scale = st.sampled_from([1.0, 1e-3, 1e-7, 1e-13])


@st.composite
def quaternions(draw) -> jnp.ndarray:
    """A unit quaternion, near the identity as often as not."""
    u = np.array([draw(_coordinate) for _ in range(3)]) * draw(_scale)
    w = draw(st.floats(0.1, 1.0)) * draw(st.sampled_from([1.0, -1.0]))
    q = np.array([w, *u])
    return jnp.asarray(q / np.linalg.norm(q))


@st.composite
def vectors(draw, size: float = 10.0) -> jnp.ndarray:
    return jnp.asarray([draw(st.floats(-size, size)) for _ in range(3)])


@st.composite
def rotation_vectors(draw) -> jnp.ndarray:
    """A rotation vector of angle below π (where the logarithm is its inverse)."""
    v = np.array([draw(_coordinate) for _ in range(3)])
    norm = np.linalg.norm(v)
    if norm == 0.0:
        return jnp.zeros(3)
    angle = draw(st.floats(0.0, np.pi - 1e-3)) * draw(_scale)
    return jnp.asarray(v / norm * angle)


def close(a, b, tol: float = TOL) -> None:
    np.testing.assert_allclose(np.asarray(a), np.asarray(b), rtol=0, atol=tol)


def same_rotation(p, q) -> None:
    """``p`` and ``q`` are the same rotation: equal up to sign."""
    sign = np.sign(np.dot(np.asarray(p), np.asarray(q))) or 1.0
    close(p, sign * np.asarray(q))


@given(quaternions(), quaternions(), quaternions())
def test_composition_is_associative(p, q, r):
    close(rot.multiply(rot.multiply(p, q), r), rot.multiply(p, rot.multiply(q, r)))


@given(quaternions(), vectors())
def test_the_identity_changes_nothing(q, v):
    close(rot.multiply(IDENTITY, q), q)
    close(rot.multiply(q, IDENTITY), q)
    close(rot.rotate(IDENTITY, v), v)
    close(rot.matrix(IDENTITY), np.eye(3))


@given(quaternions(), vectors())
def test_the_conjugate_is_the_inverse(q, v):
    close(rot.multiply(q, rot.conjugate(q)), IDENTITY)
    close(rot.multiply(rot.conjugate(q), q), IDENTITY)
    close(rot.rotate(rot.conjugate(q), rot.rotate(q, v)), v)


@given(quaternions(), quaternions(), vectors())
def test_the_product_rotates_by_the_second_then_the_first(p, q, v):
    close(rot.matrix(rot.multiply(p, q)), rot.matrix(p) @ rot.matrix(q))
    close(rot.rotate(rot.multiply(p, q), v), rot.rotate(p, rot.rotate(q, v)))


@given(quaternions(), vectors())
def test_rotating_by_a_quaternion_equals_rotating_by_its_matrix(q, v):
    close(rot.rotate(q, v), rot.matrix(q) @ v)
    close(rot.np_matrix(np.asarray(q)), rot.matrix(q))


@given(quaternions())
def test_the_matrix_is_a_rotation(q):
    r = np.asarray(rot.matrix(q))
    close(r.T @ r, np.eye(3))
    assert np.linalg.det(r) == pytest.approx(1.0, abs=TOL)


@given(quaternions())
def test_quaternion_matrix_quaternion_round_trip(q):
    back = rot.np_from_matrix(rot.np_matrix(np.asarray(q)))
    assert back[0] >= 0.0
    same_rotation(back, q)


@given(quaternions(), st.floats(0.1, 10.0), vectors())
def test_normalisation(q, c, v):
    """``rotate`` is the quadratic form (``c q`` scales by ``c²``, the solver's states
    need not be unit); ``np_matrix`` normalises; the exponential is unit."""
    close(rot.rotate(c * q, v), c * c * rot.rotate(q, v), TOL * c * c)
    close(rot.np_matrix(c * np.asarray(q)), rot.np_matrix(np.asarray(q)))
    assert float(jnp.linalg.norm(rot.rotate(q, v))) == pytest.approx(
        float(jnp.linalg.norm(v)), abs=TOL
    )


@given(rotation_vectors())
def test_log_inverts_exp(omega):
    close(rot.quaternion_log(rot.quaternion_exp(omega)), omega)
    assert float(jnp.linalg.norm(rot.quaternion_exp(omega))) == pytest.approx(
        1.0, abs=TOL
    )


@given(quaternions())
def test_exp_inverts_log(q):
    same_rotation(rot.quaternion_exp(rot.quaternion_log(q)), q)
    assert float(jnp.linalg.norm(rot.quaternion_log(q))) <= np.pi + TOL
    close(rot.quaternion_log(-q), rot.quaternion_log(q))


@given(rotation_vectors(), vectors())
def test_the_matrix_exponential_is_the_quaternions(omega, v):
    close(rot.matrix_exp(omega), rot.matrix(rot.quaternion_exp(omega)))
    close(rot.matrix_exp(omega) @ v, rot.rotate(rot.quaternion_exp(omega), v))


@given(rotation_vectors())
def test_axis_angle_is_the_exponential_of_the_rotation_vector(omega):
    angle = float(jnp.linalg.norm(omega))
    if angle == 0.0:
        return
    axis = omega / angle
    q = rot.from_axis_angle(axis, angle)
    close(q, rot.quaternion_exp(omega))
    close(rot.axis_angle_matrix(axis, angle), rot.matrix(q))
    close(rot.np_axis_angle_matrix(np.asarray(axis), angle), rot.matrix(q))


@given(
    st.floats(-np.pi, np.pi),
    st.floats(-np.pi / 2 + 1e-3, np.pi / 2 - 1e-3),
    st.floats(-np.pi, np.pi),
)
def test_roll_pitch_yaw_rebuild_the_matrix(roll, pitch, yaw):
    e = np.eye(3)
    r = (
        rot.np_axis_angle_matrix(e[2], yaw)
        @ rot.np_axis_angle_matrix(e[1], pitch)
        @ rot.np_axis_angle_matrix(e[0], roll)
    )
    angles = rot.np_rpy(r)
    rebuilt = (
        rot.np_axis_angle_matrix(e[2], angles[2])
        @ rot.np_axis_angle_matrix(e[1], angles[1])
        @ rot.np_axis_angle_matrix(e[0], angles[0])
    )
    close(rebuilt, r)
    assert angles[1] == pytest.approx(pitch, abs=1e-9)


@given(vectors(), vectors(), vectors())
def test_turn_onto_is_the_rotation_taking_one_direction_to_the_other(a, b, d):
    u, v = rot.unit(jnp, a), rot.unit(jnp, b)
    if float(jnp.linalg.norm(a)) < 1e-3 or float(jnp.linalg.norm(b)) < 1e-3:
        return
    if float(jnp.dot(u, v)) < -0.99:  # near v = -u the axis is ill-defined
        return
    close(rot.turn_onto(jnp, u, v, u), v)
    close(
        rot.turn_onto(np, np.asarray(u), np.asarray(v), np.asarray(d)),
        rot.turn_onto(jnp, u, v, d),
    )
    axis = jnp.cross(u, v)
    angle = float(jnp.arctan2(jnp.linalg.norm(axis), jnp.dot(u, v)))
    omega = axis / max(float(jnp.linalg.norm(axis)), 1e-300) * angle
    close(rot.turn_onto(jnp, u, v, d), rot.matrix_exp(omega) @ d)


def test_the_unit_of_zero_is_zero_with_a_finite_gradient():
    close(rot.unit(jnp, jnp.zeros(3)), np.zeros(3))
    close(rot.unit(np, np.array([3.0, 0.0, 4.0])), [0.6, 0.0, 0.8])
    gradient = jax.grad(lambda v: jnp.sum(rot.unit(jnp, v)))(jnp.zeros(3))
    assert np.all(np.isfinite(np.asarray(gradient)))


def test_derivatives_at_the_identity_are_finite_and_exact():
    """``d exp(ω)/dω = [0; I/2]`` and ``d log(q)/du = 2 I`` at the identity; the matrix
    exponential's derivative is the generator ``d([ω]× v)/dω = -[v]×``."""
    zero = jnp.zeros(3)
    close(jax.jacfwd(rot.quaternion_exp)(zero), np.vstack([np.zeros(3), np.eye(3) / 2]))
    close(jax.jacrev(rot.quaternion_exp)(zero), np.vstack([np.zeros(3), np.eye(3) / 2]))
    close(jax.jacrev(rot.quaternion_log)(IDENTITY)[:, 1:], 2.0 * np.eye(3))
    v = jnp.array([0.3, -1.2, 0.7])
    generator = jax.jacrev(lambda w: rot.matrix_exp(w) @ v)(zero)
    x, y, z = np.asarray(v)
    close(generator, -np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]]))
