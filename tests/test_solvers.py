"""The solver protocol (``linkopt._engine.solvers``): each solver on problems with
closed-form solutions converges to them with ``Result.SUCCESSFUL``, reports a stall as
``STALLED`` and stops at the driver's iteration cap with ``MAX_ITERATIONS``."""

from __future__ import annotations

from dataclasses import dataclass

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import linkopt  # noqa: F401  (float64)
from linkopt._engine.solvers.driver import Result, run
from linkopt._engine.solvers.lm import (
    LevenbergMarquardt,
    MinimumNorm,
    NormalEquations,
    value_and_jacobian,
)
from linkopt._engine.solvers.projection import Projection
from linkopt._engine.solvers.quasi_newton import QuasiNewton


def rosenbrock(x):
    return jnp.stack([10.0 * (x[1] - x[0] ** 2), 1.0 - x[0]])


def lm(fn, tolerance=1e-12):
    return LevenbergMarquardt(NormalEquations(fn), tolerance, 1e-3)


def test_lm_finds_the_rosenbrock_minimum():
    state, result = jax.jit(lambda x: run(lm(rosenbrock), x, 100))(
        jnp.array([-1.2, 1.0])
    )
    assert int(result) == Result.SUCCESSFUL
    np.testing.assert_allclose(state.x, [1.0, 1.0], atol=1e-10)
    assert 0 < int(state.iteration) < 100


def test_lm_stops_at_the_iteration_cap():
    state, result = run(lm(rosenbrock), jnp.array([-1.2, 1.0]), 2)
    assert int(result) == Result.MAX_ITERATIONS
    assert int(state.iteration) == 2


def test_lm_reports_a_nonzero_minimum_as_a_stall():
    """``x - 1`` and ``x + 1`` cannot both vanish; LM ends at their least squares
    point ``x = 0`` and says it stalled rather than running to the cap."""
    state, result = run(
        lm(lambda x: jnp.concatenate([x - 1.0, x + 1.0])), jnp.ones(1), 500
    )
    assert int(result) == Result.STALLED
    assert int(state.iteration) < 500
    np.testing.assert_allclose(state.x, [0.0], atol=1e-7)


def test_lm_runs_batched():
    starts = jnp.array([[-1.2, 1.0], [0.5, 0.5], [2.0, 3.0]])
    states, results = jax.vmap(lambda x: run(lm(rosenbrock), x, 100))(starts)
    assert np.all(np.asarray(results) == Result.SUCCESSFUL)
    np.testing.assert_allclose(states.x, np.ones((3, 2)), atol=1e-10)


def test_the_residual_is_traced_once_per_linearisation():
    calls = []

    def counted(x):
        calls.append(1)
        return rosenbrock(x)

    jacobian, value = value_and_jacobian(counted, jnp.array([0.3, 0.7]))
    assert len(calls) == 1
    np.testing.assert_array_equal(value, rosenbrock(jnp.array([0.3, 0.7])))
    np.testing.assert_allclose(
        jacobian, jax.jacobian(rosenbrock)(jnp.array([0.3, 0.7]))
    )


def test_minimum_norm_lm_finds_the_least_norm_solution():
    """``x₀ + 2x₁ = 5`` from the origin: the nearest solution is ``(1, 2)``."""
    method = MinimumNorm(lambda x: jnp.array([x[0] + 2.0 * x[1] - 5.0]), jnp.ones(2))
    state, result = run(LevenbergMarquardt(method, 1e-14, 1e-6), jnp.zeros(2), 50)
    assert int(result) == Result.SUCCESSFUL
    np.testing.assert_allclose(state.x, [1.0, 2.0], atol=1e-10)


def circle(x):  # or the sphere, in 3-D
    return jnp.array([x @ x - 1.0])


def test_projection_finds_the_point_of_the_circle_nearest_the_anchor():
    """Gauss–Newton ignores the circle's curvature: it converges (linearly) for an
    anchor nearer the circle than its centre of curvature."""
    anchor = jnp.array([0.8, 0.8])
    solver = Projection(MinimumNorm(circle, jnp.ones(2)), anchor)
    state, result = jax.jit(lambda x: run(solver, x, 100))(jnp.array([1.0, 0.0]))
    assert int(result) == Result.SUCCESSFUL
    np.testing.assert_allclose(state.x, [0.5**0.5, 0.5**0.5], atol=1e-12)


def test_projection_holds_a_variable_of_scale_zero():
    """On the unit sphere with ``x₀`` held at 0.6, the point nearest ``(0.6, 0.6,
    0.6)`` is ``(0.6, 0.8/√2, 0.8/√2)``."""
    anchor = jnp.array([0.6, 0.6, 0.6])
    solver = Projection(MinimumNorm(circle, jnp.array([0.0, 1.0, 1.0])), anchor)
    state, result = run(solver, jnp.array([0.6, 0.8, 0.0]), 100)
    assert int(result) == Result.SUCCESSFUL
    np.testing.assert_allclose(state.x, [0.6, 0.32**0.5, 0.32**0.5], atol=1e-12)


def test_projection_stops_at_the_iteration_cap():
    solver = Projection(MinimumNorm(circle, jnp.ones(2)), jnp.array([0.8, 0.8]))
    state, result = run(solver, jnp.array([1.0, 0.0]), 1)
    assert int(result) == Result.MAX_ITERATIONS
    assert int(state.iteration) == 1


@dataclass(frozen=True)
class Quadratic:
    """``½|A x - b|²`` with its Gauss–Newton matrix ``AᵀA``; a point is ``x`` itself.
    ``fails`` makes every trial fail."""

    a: jnp.ndarray
    b: jnp.ndarray
    fails: bool = False

    def trial(self, state, delta, fresh):
        return state.x + delta, jnp.asarray(not self.fails)

    def evaluate(self, x, trial):
        r = self.a @ x - self.b
        return 0.5 * r @ r, self.a.T @ r, self.a.T @ self.a, trial


A = jnp.array([[2.0, 1.0], [0.0, 3.0]])
B = jnp.array([1.0, -2.0])


@pytest.mark.parametrize("bfgs", [False, True])
def test_quasi_newton_finds_the_minimum_of_a_quadratic(bfgs):
    solver = QuasiNewton(Quadratic(A, B), max_step=0.5, bfgs=bfgs)
    state, result = jax.jit(lambda y: run(solver, y, 200))((jnp.zeros(2), jnp.zeros(2)))
    assert int(result) == Result.SUCCESSFUL
    np.testing.assert_allclose(state.x, np.linalg.solve(A, B), atol=1e-8)
    np.testing.assert_allclose(state.point, state.x)  # the point follows x


def test_quasi_newton_keeps_steps_within_the_trust_radius():
    """From a start 2 units away with ``max_step`` 0.1, growth 4: a step is at most
    0.4 long, so reaching the minimum takes at least 5 steps."""
    solver = QuasiNewton(Quadratic(jnp.eye(2), jnp.array([2.0, 0.0])), max_step=0.1)
    state, result = run(solver, (jnp.zeros(2), jnp.zeros(2)), 200)
    assert int(result) == Result.SUCCESSFUL
    np.testing.assert_allclose(state.x, [2.0, 0.0], atol=1e-8)
    assert int(state.iteration) >= 5


def test_quasi_newton_stalls_when_every_trial_fails():
    solver = QuasiNewton(Quadratic(A, B, fails=True), max_step=0.5)
    state, result = run(solver, (jnp.zeros(2), jnp.zeros(2)), 1000)
    assert int(result) == Result.STALLED
    assert int(state.iteration) < 1000
    np.testing.assert_array_equal(state.x, [0.0, 0.0])  # no step accepted


def test_quasi_newton_stops_at_the_iteration_cap():
    solver = QuasiNewton(Quadratic(jnp.eye(2), jnp.array([2.0, 0.0])), max_step=0.1)
    state, result = run(solver, (jnp.zeros(2), jnp.zeros(2)), 3)
    assert int(result) == Result.MAX_ITERATIONS
    assert int(state.iteration) == 3
