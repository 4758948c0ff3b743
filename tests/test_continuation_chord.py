"""The chord steps of the continuation on the band
(:mod:`linkopt._engine.solvers.chord`, :func:`linkopt._engine.banded.predict`): the
chord loop's stopping rules on a scalar equation, the order of the predictions'
errors in the step (first order: the step squared; one chord step: the step cubed),
and from-rest solves on the band equal to the walk without chord steps
with at most one LM iteration a solve."""

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from conftest import MECHANISMS
from long_linkages import ladder, ladder_cells

import linkopt
from linkopt._engine import banded, continuation, kinematics
from linkopt._engine.constraints import (
    homogenised_motor_values,
    homogenised_output_values,
)
from linkopt._engine.geometry import design_vector, geometry, rest_state
from linkopt._engine.solvers import chord


def _with_factor(mech, factor: str):
    return dataclasses.replace(
        mech, solver=dataclasses.replace(mech.solver, factor=factor)
    )


def test_the_chord_loop_stops_at_the_tolerance_and_keeps_no_worse_step():
    """``x² = 2`` from 1.4 with the slope at 1.4: converges linearly to the tolerance;
    with the slope's sign wrong every step raises ``|C|`` and the start comes back;
    with a slope far off (rate 0.6 > CONTRACTION) the loop stops after one kept
    step."""
    residual = lambda x: x**2 - 2.0  # noqa: E731
    root = np.sqrt(2.0)
    x = chord.solve(residual, lambda r: r / 2.8, jnp.asarray(1.4), tolerance=1e-13)
    assert abs(float(x) - root) < 1e-13
    back = chord.solve(residual, lambda r: -r / 2.8, jnp.asarray(1.4), tolerance=1e-13)
    assert float(back) == 1.4
    slow = chord.solve(residual, lambda r: r / 7.0, jnp.asarray(1.4), tolerance=1e-13)
    once = 1.4 - float(residual(1.4)) / 7.0
    assert float(slow) == pytest.approx(once, abs=1e-15)
    capped = chord.solve(
        residual, lambda r: r / 2.8, jnp.asarray(1.4), tolerance=1e-13, limit=1
    )
    assert float(capped) == pytest.approx(1.4 - float(residual(1.4)) / 2.8, abs=1e-15)


@pytest.mark.parametrize("kind", ["fk", "bk"])
def test_a_chord_step_makes_the_prediction_second_order(kind):
    """Five-bar on the band: halving the step divides the first-order prediction's
    error by about 4 and the error after one chord step by about 8."""
    mech = _with_factor(linkopt.load(MECHANISMS / "five_bar.toml"), "banded")
    geom = geometry(mech, design_vector(mech, None))
    state = rest_state(mech)
    read = {"fk": homogenised_motor_values, "bk": homogenised_output_values}[kind]
    values = read(mech, geom, state)
    direction = jnp.asarray([1.0, -0.6])[: values.size]
    errors = []
    for h in (0.08, 0.04, 0.02):
        target = values + h * direction
        first, once = banded.predict(mech, kind, geom, target, state, 1)
        exact = continuation.corrector(mech, kind, geom, target, once).x
        errors.append([float(jnp.max(jnp.abs(p - exact))) for p in (first, once)])
    errors = np.asarray(errors)
    first_rates = errors[:-1, 0] / errors[1:, 0]
    chord_rates = errors[:-1, 1] / errors[1:, 1]
    assert np.all((first_rates > 3.0) & (first_rates < 5.0)), errors
    assert np.all((chord_rates > 6.0) & (chord_rates < 10.0)), errors
    assert np.all(errors[:, 1] < 0.2 * errors[:, 0])


def _from_rest(mech, rows):
    """:func:`kinematics.continue_to` from rest to each row, vmapped in a program of
    its own (traced now, so with the chord limit set now)."""
    geom = geometry(mech, design_vector(mech, None))
    start = rest_state(mech)
    v_rest = homogenised_motor_values(mech, geom, start)

    def one(v):
        return kinematics.continue_to(mech, "fk", geom, v_rest, start, v)

    return jax.jit(jax.vmap(one))(jnp.asarray(rows) / mech.motor_scale)


def test_a_ladder_from_rest_with_chord_steps_equals_the_walk_without(monkeypatch):
    """A ladder of ``MIN_BODIES + 4`` bodies (the band by default) from rest: the same
    states as the walk without chord steps (``LIMIT`` 0), and the chord steps leave
    the LM corrector at most one iteration a solve where it took several."""
    mech = linkopt.loads(ladder(ladder_cells(banded.MIN_BODIES + 4)), "ladder.toml")
    assert banded.serves(mech)
    rest = np.asarray(linkopt.motor_values(mech, rest_state(mech)))
    rows = rest + np.random.default_rng(0).uniform(-0.1, 0.1, (3, rest.size))
    got = _from_rest(mech, rows)
    monkeypatch.setattr(chord, "LIMIT", 0)
    want = _from_rest(mech, rows)
    assert np.all(np.asarray(got.converged)) and np.all(np.asarray(want.converged))
    np.testing.assert_allclose(got.state, want.state, rtol=0, atol=1e-9)
    assert np.all(np.asarray(got.iterations) <= 1)
    assert np.mean(np.asarray(want.iterations)) >= 2


def test_the_band_prediction_without_chord_steps_is_the_dense_one():
    mech = linkopt.load(MECHANISMS / "jansen_2dof.toml")
    geom = geometry(mech, design_vector(mech, None))
    state = rest_state(mech)
    target = homogenised_motor_values(mech, geom, state) + 0.05
    dense = continuation.predict(mech, "fk", geom, target, state)
    first, same = banded.predict(
        _with_factor(mech, "banded"), "fk", geom, target, state
    )
    np.testing.assert_array_equal(first, same)
    np.testing.assert_allclose(first, dense, rtol=0, atol=1e-10)
