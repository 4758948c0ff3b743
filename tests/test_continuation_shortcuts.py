"""The continuation's prediction from the corrector's last linearisation
(:func:`linkopt._engine.continuation.predict_from`) against the prediction built from
scratch (:func:`~linkopt._engine.continuation.predict`), the Jacobian of the rows it
updates (:func:`linkopt._engine.jacobian.normal_equations_tail`) against the full
linearisation, and the linearisation that an LM solve hands back against one built at
its answer."""

import jax.numpy as jnp
import numpy as np
import pytest

import linkopt
from linkopt._engine import continuation, jacobian, kinematics
from linkopt._engine.constraints import (
    homogenised_motor_values,
    homogenised_output_values,
)
from linkopt._engine.geometry import design_vector, geometry, rest_state

VALUES = {"fk": homogenised_motor_values, "bk": homogenised_output_values}
TOL = 1e-12


def _setup(name: str, kind: str, seed: int):
    mech = linkopt.load(f"mechanisms/{name}.toml")
    geom = geometry(mech, design_vector(mech, None))
    state = rest_state(mech)
    v0 = VALUES[kind](mech, geom, state)
    step = np.random.default_rng(seed).uniform(-0.08, 0.08, v0.shape)
    return mech, geom, state, v0, v0 + jnp.asarray(step)


@pytest.mark.parametrize("kind", ["fk", "bk"])
@pytest.mark.parametrize("name", ["five_bar", "jansen_2dof"])
def test_tail_jacobian_is_the_last_rows_of_the_linearisation(name, kind):
    mech, geom, state, _, values = _setup(name, kind, 0)
    state = state + 1e-3 * jnp.asarray(np.random.default_rng(1).normal(size=state.size))
    residual, jac = jacobian.linearise(mech, geom, kind, values, state)
    *normal, tail_jac = jacobian.normal_equations_tail(mech, geom, kind, values, state)
    assert tail_jac.shape == (values.shape[0], state.size)
    np.testing.assert_allclose(tail_jac, jac[-tail_jac.shape[0] :], rtol=0, atol=TOL)
    plain = jacobian.normal_equations(mech, geom, kind, values, state)
    for got, want in zip(normal, plain, strict=True):
        np.testing.assert_array_equal(got, want)


@pytest.mark.parametrize("seed", range(3))
@pytest.mark.parametrize(
    ("name", "kind"), [("five_bar", "fk"), ("five_bar", "bk"), ("jansen_2dof", "fk")]
)
def test_prediction_from_the_last_linearisation_equals_a_fresh_one(name, kind, seed):
    """A state solved at ``v0`` (the rest state, and a state that LM solved at
    ``v1``), predicted at other values both ways."""
    mech, geom, state, v0, v1 = _setup(name, kind, seed)
    known = continuation.start_linearisation(mech, kind, geom, v0, state)
    fresh = continuation.predict(mech, kind, geom, v1, state)
    reused = continuation.predict_from(state, known, v1 - v0)
    assert float(jnp.max(jnp.abs(fresh - state))) > 1e-3  # a real move
    np.testing.assert_allclose(reused, fresh, rtol=0, atol=1e-10)

    result = continuation.corrector(mech, kind, geom, v1, fresh, with_tail=True)
    assert bool(result.converged)
    v2 = v1 + (v1 - v0)
    fresh = continuation.predict(mech, kind, geom, v2, result.x)
    reused = continuation.predict_from(result.x, result.linearisation, v2 - v1)
    np.testing.assert_allclose(reused, fresh, rtol=0, atol=1e-10)


def test_lm_hands_back_the_linearisation_at_its_answer():
    mech, geom, state, _, v1 = _setup("five_bar", "fk", 4)
    result = continuation.corrector(mech, "fk", geom, v1, state)
    assert bool(result.converged) and int(result.iterations) > 1
    residual, (hessian, gradient) = result.linearisation
    fresh = jacobian.normal_equations(mech, geom, "fk", v1, result.x)
    for got, want in zip((residual, hessian, gradient), fresh, strict=True):
        np.testing.assert_allclose(got, want, rtol=0, atol=TOL)


def test_walk_starts_from_the_linearisation_at_its_start():
    mech, geom, state, v0, _ = _setup("five_bar", "fk", 5)
    residual, (hessian, gradient, tail) = continuation.start_linearisation(
        mech, "fk", geom, v0, state
    )
    jac = jacobian.state_jacobian(mech, geom, "fk", state)
    np.testing.assert_allclose(tail, jac[-tail.shape[0] :], rtol=0, atol=TOL)
    np.testing.assert_allclose(hessian, jac.T @ jac, rtol=0, atol=1e-10)
    np.testing.assert_allclose(gradient, jac.T @ residual, rtol=0, atol=TOL)


def test_a_batch_from_rest_is_solved_in_span_order_and_put_back():
    """The rows go through the chunks sorted by span (``kinematics.span_order``), and
    come back in the caller's order: each state carries its own row's motor values,
    and a reversed batch gives the same states reversed, bit for bit (a row's solve
    does not depend on its neighbours)."""
    mech = linkopt.load("mechanisms/five_bar.toml")
    rest = np.asarray(linkopt.motor_values(mech, linkopt.rest_state(mech)))
    rng = np.random.default_rng(3)
    rows = rest + rng.uniform(-0.3, 0.3, (150, rest.size)) * mech.motor_scale
    order = kinematics.span_order(mech, "fk", rows)
    span = np.max(np.abs(rows - rest) / mech.motor_scale, axis=1)
    assert np.all(np.diff(span[order]) >= -1e-12)
    assert not np.array_equal(order, np.arange(len(rows)))  # a real shuffle

    solution = linkopt.solve_fk(mech, rows)
    assert np.all(np.asarray(solution.converged))
    read = np.asarray(linkopt.motor_values(mech, solution.state))
    np.testing.assert_allclose(read, rows, rtol=0, atol=1e-9)
    reverse = linkopt.solve_fk(mech, rows[::-1])
    np.testing.assert_array_equal(np.asarray(reverse.state)[::-1], solution.state)
    np.testing.assert_array_equal(
        np.asarray(reverse.iterations)[::-1], solution.iterations
    )
