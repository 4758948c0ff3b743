"""The per-body rotation matrices of :mod:`linkopt._engine.turns` against the quaternion
formulas they replace in the constraint Jacobian: on random states, quaternions off
the unit sphere included (the solver's states are), ``R v`` equals
:func:`~linkopt._engine.rotations.rotate`, ``∂(R v)/∂q`` equals ``jax.jacfwd`` of it
and the closed form of :func:`~linkopt._engine.row_algebra.rotate_grad`, and
``∂(a · R v)/∂q`` equals :func:`~linkopt._engine.row_algebra.dot_grad`, to 1e-12;
both ways of applying them (contractions, and the unrolled element-wise sums of the
solves' linearisations) alike."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from linkopt._engine import rotations, turns
from linkopt._engine.rotations import rotate
from linkopt._engine.row_algebra import dot_grad, rotate_grad

TOL = 1e-12
SEEDS = range(4)
WAYS = [False, True]  # Turn.unrolled


def _draw(seed: int, count: int = 32):
    """Quaternions of norm 0.5 to 1.5 (a quarter exactly unit, one the identity),
    body-local vectors and world vectors."""
    rng = np.random.default_rng(seed)
    q = rng.normal(size=(count, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    q[count // 4 :] *= rng.uniform(0.5, 1.5, size=(count - count // 4, 1))
    q[0] = [1.0, 0.0, 0.0, 0.0]
    v = rng.normal(size=(count, 3)) * 3.0
    a = rng.normal(size=(count, 3))
    return jnp.asarray(q), jnp.asarray(v), jnp.asarray(a)


def test_quadratic_form_is_symmetric_with_unit_entries():
    q = rotations.QUADRATIC
    assert np.array_equal(q, np.swapaxes(q, -1, -2))
    assert set(np.unique(q)) <= {-1.0, 0.0, 1.0}


@pytest.mark.parametrize("unrolled", WAYS)
@pytest.mark.parametrize("seed", SEEDS)
def test_matrix_rotates_as_the_quaternion_formula(seed, unrolled):
    q, v, _ = _draw(seed)
    turn = turns.body_turns(q, unrolled)
    np.testing.assert_allclose(turns.turned(turn, v), rotate(q, v), rtol=0, atol=TOL)


@pytest.mark.parametrize("seed", SEEDS)
def test_unit_quaternion_gives_an_orthonormal_matrix(seed):
    q, _, _ = _draw(seed)
    unit = q / jnp.linalg.norm(q, axis=1, keepdims=True)
    m = turns.body_turns(unit).matrix
    eye = np.broadcast_to(np.eye(3), m.shape)
    np.testing.assert_allclose(m @ jnp.swapaxes(m, -1, -2), eye, atol=TOL)
    np.testing.assert_allclose(jnp.linalg.det(m), 1.0, atol=TOL)


@pytest.mark.parametrize("unrolled", WAYS)
@pytest.mark.parametrize("seed", SEEDS)
def test_slope_is_the_derivative_of_the_rotation(seed, unrolled):
    q, v, _ = _draw(seed)
    slope = turns.turned_slope(turns.body_turns(q, unrolled), v)
    forward = jax.vmap(jax.jacfwd(rotate), in_axes=(0, 0))(q, v)
    np.testing.assert_allclose(slope, forward, rtol=0, atol=TOL)
    np.testing.assert_allclose(slope, rotate_grad(q, v), rtol=0, atol=TOL)


@pytest.mark.parametrize("unrolled", WAYS)
@pytest.mark.parametrize("seed", SEEDS)
def test_side_dot_grad_equals_the_quaternion_closed_form(seed, unrolled):
    q, v, a = _draw(seed)
    side = turns.Side(turns.body_turns(q, unrolled))
    np.testing.assert_allclose(side.dot_grad(v, a), dot_grad(q, v, a), atol=TOL)
    np.testing.assert_allclose(side.rot(v), rotate(q, v), rtol=0, atol=TOL)


@pytest.mark.parametrize("unrolled", WAYS)
def test_side_builds_each_vector_once(unrolled):
    q, v, a = _draw(0, 4)
    side = turns.Side(turns.body_turns(q, unrolled))
    assert side.rot(v) is side.rot(v)
    assert side.slope(v) is side.slope(v)
    assert side.rot(a) is not side.rot(v)


def test_take_turn_gathers_bodies():
    q, _, _ = _draw(1, 6)
    turn = turns.body_turns(q)
    index = np.array([4, 1, 1])
    taken = turns.take_turn(turn, index)
    np.testing.assert_array_equal(taken.matrix, turn.matrix[index])
    np.testing.assert_array_equal(taken.slope, turn.slope[index])


def test_unrolled_turns_have_no_dot_operation():
    """The unrolled way is element-wise: no ``dot_general`` in its jaxpr (XLA:CPU
    runs each contraction as a dot of its own, outside the fused element-wise code:
    the solves' linearisations were 10-40 % slower with them)."""
    q, v, a = _draw(2, 8)

    def grads(q, v, a, unrolled):
        side = turns.Side(turns.body_turns(q, unrolled))
        return side.rot(v), side.dot_grad(v, a)

    def primitives(unrolled):
        jaxpr = jax.make_jaxpr(lambda *x: grads(*x, unrolled))(q, v, a)
        return str(jaxpr)

    assert "dot_general" in primitives(False)
    body = primitives(True)
    assert body.count("dot_general") == 2  # R and its slope from q, once per body
    np.testing.assert_allclose(
        grads(q, v, a, True)[1], grads(q, v, a, False)[1], rtol=0, atol=TOL
    )
