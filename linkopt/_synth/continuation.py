"""The cycle swept by continuation for a batch of designs in lockstep:
each row's state from the last by the engine's prediction and Gauss–Newton
corrections, and ``σ_min^FK`` tracked by inverse iteration along the way. The score
built on it is :mod:`.objective`'s.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from .._engine import dense
from .._engine.constraints import fk_residual, homogenised_motor_values
from .._engine.continuation import PREDICTION_RATIO, PREDICTION_SLACK
from .._engine.geometry import rest_state
from .._engine.jacobian import normal_equations
from .._engine.kinematics import continue_to
from .._engine.model import Mechanism

#: Gauss–Newton corrections after each row's prediction (:func:`step_to`): from a
#: prediction off by ``O(h²)`` (``h`` the row's step, 1° on a 360-row turn) two
#: quadratic steps reach the solver tolerance; a coarser sweep takes up to
#: ``MORE_CORRECTIONS`` more on the rows that need them.
CORRECTIONS = 2
MORE_CORRECTIONS = 6
#: Inverse iterations for ``σ_min`` at the first row (:func:`sweep`).
FIRST_ITERATIONS = 8


def _newton(mech: Mechanism, geom, values, state):
    """One Gauss–Newton step on ``C_FK(values, s) = 0`` from ``state`` (the engine's
    first-order prediction, :func:`linkopt._engine.continuation.predict`), the largest
    residual before it and ``JᵀJ`` there."""
    residual, hessian, gradient = normal_equations(mech, geom, "fk", values, state)
    new = state - dense.damped_solve(hessian, 1e-12, gradient)
    return new, jnp.max(jnp.abs(residual)), hessian


def _corrected(mech: Mechanism, geom, values, predicted, count: int):
    """``count`` (at least one) Gauss–Newton corrections of a prediction, fewer
    where the residual is already within the solver tolerance; and the last
    ``JᵀJ``."""
    n = predicted.shape[-1]

    def correct(_, carry):
        current, _ = carry
        new, residual, hessian = _newton(mech, geom, values, current)
        return jnp.where(residual > mech.solver.tolerance, new, current), hessian

    start = (predicted, jnp.zeros((n, n), predicted.dtype))
    # a loop, not unrolled: one traced correction whatever the count (the sweep's
    # program compiled several times faster)
    return jax.lax.fori_loop(0, count, correct, start)


def _verdict(mech: Mechanism, geom, values, state, predicted, current):
    """Whether ``current`` is accepted (:func:`step_to`)."""
    residual = jnp.max(jnp.abs(fk_residual(mech, geom, values, current)))
    correction = jnp.max(jnp.abs(current - predicted))
    move = jnp.max(jnp.abs(predicted - state))
    return (residual <= mech.solver.tolerance) & (
        correction <= PREDICTION_RATIO * move + PREDICTION_SLACK
    )


def step_to(mech: Mechanism, geoms, states, values, alive):
    """Every design's state at motor ``values`` from its state solved at nearby
    values (leading axis ``D`` on ``geoms`` and ``states``): the prediction, then
    :data:`CORRECTIONS` Gauss–Newton corrections, and for a batch where some design
    is not yet accepted :data:`MORE_CORRECTIONS` more for all (a branch taken once
    for the batch, so the usual step costs the fixed count alone; designs no longer
    ``alive``, whose sweep has ended, do not count). Accepted (``ok``)
    when the residual is within the solver tolerance and the corrections moved the
    prediction by at most half the predicted move (plus ``PREDICTION_SLACK``): the
    engine's continuation test (:mod:`linkopt._engine.kinematics`) that tells the
    branch from a jump to another assembly. Also each design's last ``JᵀJ``."""
    batch = jax.vmap
    predicted = batch(lambda g, s: _newton(mech, g, values, s)[0])(geoms, states)
    current = batch(lambda g, p: _corrected(mech, g, values, p, CORRECTIONS))(
        geoms, predicted
    )

    def verdict(now):
        return batch(lambda g, s, p, c: _verdict(mech, g, values, s, p, c))(
            geoms, states, predicted, now
        )

    ok = verdict(current[0])

    def more(_):
        fixed = batch(lambda g, x: _corrected(mech, g, values, x, MORE_CORRECTIONS))(
            geoms, current[0]
        )
        return fixed, verdict(fixed[0])

    (state, hessian), ok = jax.lax.cond(
        jnp.all(ok | ~alive), lambda _: (current, ok), more, None
    )
    return state, ok, hessian


def _smallest(hessian, vector, count: int = 1):
    """``count`` inverse iterations of ``vector`` on ``JᵀJ`` and the Rayleigh
    estimate of ``σ_min(J) = √λ_min(JᵀJ)``."""

    def iterate(_, vector):
        vector = dense.damped_solve(hessian, 1e-14, vector)
        return vector / jnp.linalg.norm(vector)

    vector = jax.lax.fori_loop(0, count, iterate, vector)
    return vector, jnp.sqrt(jnp.maximum(vector @ hessian @ vector, 0.0) + 1e-300)


def sweep(mech: Mechanism, geoms, rows):
    """States ``(D, S, n)``, solved flags ``(D, S)`` and ``σ_min^FK`` ``(D, S)`` of
    designs ``geoms`` (leading axis ``D``) along the homogenised motor rows ``(S, M)``
    (module docstring): the first row by the engine's continuation from the rest
    pose, each next one by :func:`step_to` from the last; after a row that fails,
    none is solved. ``σ_min`` by inverse iteration on each row's ``JᵀJ``, its vector
    carried from row to row (:data:`FIRST_ITERATIONS` at the first): the smallest
    singular direction turns slowly along the cycle, so one iteration a row
    follows it (the dense sweep, :func:`linkopt._synth.cycle.sweep_cycle`, computes
    it afresh)."""
    rest = jax.lax.stop_gradient(rest_state(mech))
    geoms = jax.lax.stop_gradient(geoms)
    n = mech.state_size
    seed = jnp.asarray(np.random.default_rng(0).standard_normal(n))

    def first(geom):
        start = homogenised_motor_values(mech, geom, rest)
        solution = continue_to(mech, "fk", geom, start, rest, rows[0])
        _, hessian, _ = normal_equations(mech, geom, "fk", rows[0], solution.state)
        vector, sigma = _smallest(hessian, seed, FIRST_ITERATIONS)
        return solution.state, solution.converged, vector, sigma

    states, alive, vectors, sigma = jax.vmap(first)(geoms)

    def advance(carry, v):
        states, alive, vectors = carry
        new, ok, hessians = step_to(mech, geoms, states, v, alive)
        ok = alive & ok
        new = jnp.where(ok[:, None], new, states)
        vectors, sigmas = jax.vmap(_smallest)(hessians, vectors)
        return (new, ok, vectors), (new, ok, sigmas)

    start = (states, alive, vectors)
    _, (path, solved, sigmas) = jax.lax.scan(advance, start, rows[1:])
    path = jnp.concatenate([states[None], path])  # (S, D, n)
    solved = jnp.concatenate([alive[None], solved])
    sigmas = jnp.concatenate([sigma[None], sigmas])
    return jnp.swapaxes(path, 0, 1), solved.T, sigmas.T
