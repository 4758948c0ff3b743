"""Geodesic acceleration of the LM step on the band
(:class:`linkopt._engine.banded.Banded`): the acceleration solves the normal equations
of the residual's second derivative along the velocity (checked against central
differences and a dense solve), and on long lazy tongs, whose soft mode bends the
constraint surface, it reaches the same answer in fewer iterations than the plain
step; with LM's damping scaled by ``|C|²`` (what the walk's corrector takes there too)
in fewer still."""

import dataclasses
from functools import partial

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from long_linkages import chain
from strandbeest import strandbeest

import linkopt
from linkopt._engine import banded, continuation
from linkopt._engine.constraints import (
    RESIDUALS,
    fk_residual,
    homogenised_motor_values,
    homogenised_output_values,
)
from linkopt._engine.geometry import geometry, rest_state
from linkopt._engine.solvers import lm
from linkopt._files.fields import parse_toml
from linkopt._files.loader import build


def _tongs(bodies: int):
    mech = build(parse_toml(chain(bodies), "tongs"), "tongs", check=False)
    return dataclasses.replace(
        mech, solver=dataclasses.replace(mech.solver, factor="banded")
    )


_VALUES = {"fk": homogenised_motor_values, "bk": homogenised_output_values}


def _off_the_branch(mech, turn: float, kind: str = "fk"):
    """The motor (``kind`` "fk") or output ("bk") values moved by ``turn`` from rest
    and the first-order prediction of the state there (no chord steps): a start LM
    must correct."""
    geom = geometry(mech)
    values = _VALUES[kind](mech, geom, rest_state(mech)) + turn
    start = banded.predict(mech, kind, geom, values, rest_state(mech))[0]
    return geom, values, start


def _bend_against_differences(mech, kind, geom, values, x, damping=1e-6) -> bool:
    """Whether the accelerated step from ``x`` bends (``2 |a| <= ACCELERATION_RATIO
    |v|``), having checked it: its ``a = 2 (δ - v)`` against ``-(JᵀJ + λI)⁻¹ Jᵀ
    r_vv`` with the dense ``J`` and ``r_vv`` from central differences of the residual
    along the velocity ``v`` (the plain step), or ``δ = v`` where it does not bend."""
    size = lambda v: float(np.linalg.norm(v))  # noqa: E731
    plain = banded.Banded(mech, geom, kind, values, geodesic=False)
    bent = banded.Banded(mech, geom, kind, values)
    residual, model = plain.linearise(x)
    velocity, predicted = plain.direction(x, model, residual, damping)
    delta, predicted_bent = bent.direction(x, model, residual, damping)
    assert float(predicted_bent) == float(predicted) > 0
    velocity = np.asarray(velocity)

    closure = partial(RESIDUALS[kind], mech, geom, values)
    h = 1e-4 / np.max(np.abs(velocity))
    ahead, here, behind = (
        np.asarray(closure(x + k * h * velocity)) for k in (1.0, 0.0, -1.0)
    )
    second = (ahead - 2.0 * here + behind) / h**2
    jac = np.asarray(jax.jacfwd(closure)(x))
    normal = jac.T @ jac + damping * np.eye(jac.shape[1])
    expected = -np.linalg.solve(normal, jac.T @ second)
    bounded = 2.0 * size(expected) <= banded.ACCELERATION_RATIO * size(velocity)
    if bounded:
        scale = np.max(np.abs(expected))
        assert scale > 1e-6 * np.max(np.abs(velocity))  # a bend to find
        acceleration = 2.0 * (np.asarray(delta) - velocity)
        np.testing.assert_allclose(acceleration, expected, atol=1e-4 * scale)
    else:
        np.testing.assert_array_equal(np.asarray(delta), velocity)
    return bounded


@pytest.mark.parametrize("kind", ["fk", "bk"])
def test_the_acceleration_solves_the_normal_equations_of_the_second_derivative(kind):
    """:func:`_bend_against_differences` on 24-body tongs from the first-order
    prediction of a 0.3 rad move (it bends); from the rest pose itself with the
    values 1 rad away the bend is beyond ``ACCELERATION_RATIO`` of the velocity, and
    the step is ``v``."""
    mech = _tongs(24)
    bounds = []
    for turn, from_rest in ((0.3, False), (1.0, True)):
        geom, values, x = _off_the_branch(mech, turn, kind)
        x = rest_state(mech) if from_rest else x
        bounds.append(_bend_against_differences(mech, kind, geom, values, x))
    assert bounds == [True, False]


def test_the_acceleration_on_the_arrowhead_solves_the_same_normal_equations():
    """The same check on the arrowhead storage (a walker of four Jansen legs, its
    ground and crank numbered last), from the first-order prediction of a 0.1 rad
    crank turn (at 0.3 rad its bend is beyond ``ACCELERATION_RATIO``): the
    acceleration's two solves and its reverse pass go through the hubs' Schur
    complement and the arrowhead's permutation."""
    walker = linkopt.loads(strandbeest(4), "strandbeest.toml")
    walker = dataclasses.replace(
        walker, solver=dataclasses.replace(walker.solver, factor="banded")
    )
    geom, values, x = _off_the_branch(walker, 0.1)
    assert banded.layout(walker, geom, "fk").hubs
    assert _bend_against_differences(walker, "fk", geom, values, x)


def test_long_tongs_converge_in_fewer_iterations_with_the_acceleration():
    """Lazy tongs of 100 bodies (the smallest eigenvalue of ``JᵀJ`` 3e-8 at rest)
    from the first-order prediction of a 0.3 rad turn: the plain and the accelerated
    LM both close the loops to 1e-12, the accelerated one in fewer iterations
    (measured 13 and 9), the answers within the soft mode's freedom at that
    tolerance (measured 1.5e-9)."""
    mech = _tongs(100)
    geom, values, start = _off_the_branch(mech, 0.3)
    results = {}
    for accelerated in (False, True):
        method = banded.Banded(mech, geom, "fk", values, accelerated)
        solve = jax.jit(
            lambda x, method=method: lm.solve(
                method, x, tolerance=1e-12, max_iterations=60, initial_damping=1e-6
            )
        )
        results[accelerated] = solve(start)
    plain, bent = results[False], results[True]
    assert bool(plain.converged) and bool(bent.converged)
    assert int(bent.iterations) < int(plain.iterations)
    closed = fk_residual(mech, geom, values, bent.x)
    assert float(jnp.max(jnp.abs(closed))) <= 1e-12
    assert float(jnp.max(jnp.abs(bent.x - plain.x))) < 1e-7


def test_only_long_linkages_take_the_acceleration():
    """The walk's corrector takes it from ``GEODESIC_BODIES`` bodies on, so every
    smaller mechanism on the band keeps the plain step's program and answers."""
    assert not banded.geodesic(_tongs(banded.GEODESIC_BODIES - 2))
    assert banded.geodesic(_tongs(banded.GEODESIC_BODIES))


def test_residual_scaled_damping_follows_the_squared_residual():
    """``residual_scaled``: an accepted step multiplies ``λ`` by Nielsen's factor
    and by the fall of ``|C|²``, never below ``MIN_DAMPING`` and never above Nielsen's
    own ``λ``; a rejected step grows it as Nielsen's rule does."""
    x = jnp.zeros(2)
    residual = jnp.array([1e-2, 0.0])
    state = lm.initial_state(x, residual, None, 1e-6)
    delta = jnp.array([1e-2, 0.0])
    predicted = residual @ residual  # an exact linear model: ρ = 1
    for new, expected in (
        (jnp.array([1e-4, 0.0]), 1e-6 / 3.0 * 1e-4),
        (jnp.array([1e-12, 0.0]), lm.MIN_DAMPING),
        (jnp.array([2e-2, 0.0]), 1e-6 * 2.0),  # rejected: |C| grew
    ):
        actual = residual @ residual - new @ new
        plain = lm.update(state, x + delta, delta, predicted, new, None)
        scaled = lm.update(
            state, x + delta, delta, predicted, new, None, residual_scaled=True
        )
        assert float(scaled.damping) == pytest.approx(expected, rel=1e-12)
        assert float(scaled.damping) <= float(plain.damping)
        if actual < 0:
            assert float(scaled.damping) == float(plain.damping)


def test_long_tongs_converge_in_fewer_iterations_with_residual_scaled_damping():
    """Lazy tongs of ``GEODESIC_BODIES`` bodies from the first-order prediction of a
    0.2 rad turn, accelerated: Nielsen's rule and the walk's corrector (which scales
    the damping with ``|C|²`` from that size on) both close the loops to the file's
    tolerance, the corrector in fewer iterations (measured 9 and 3 at 100 bodies),
    the answers within the soft mode's freedom at that tolerance (measured
    2e-11)."""
    mech = _tongs(banded.GEODESIC_BODIES)
    settings = mech.solver
    geom, values, start = _off_the_branch(mech, 0.2)
    method = banded.Banded(mech, geom, "fk", values)
    nielsen = jax.jit(
        lambda x: lm.solve(
            method,
            x,
            tolerance=settings.tolerance,
            max_iterations=settings.max_iterations,
            initial_damping=settings.initial_damping,
        )
    )(start)
    corrector = jax.jit(lambda x: continuation.corrector(mech, "fk", geom, values, x))
    scaled = corrector(start)
    assert bool(nielsen.converged) and bool(scaled.converged)
    assert int(scaled.iterations) < int(nielsen.iterations)
    closed = fk_residual(mech, geom, values, scaled.x)
    assert float(jnp.max(jnp.abs(closed))) <= settings.tolerance
    assert float(jnp.max(jnp.abs(scaled.x - nielsen.x))) < 1e-7
