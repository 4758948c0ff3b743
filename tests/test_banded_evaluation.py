"""The design evaluation on the banded path (issue 43): σ_min, ``ds/da`` and the
adjoint of the partial gradient from the banded (or arrowhead) factor wherever the
solves take it, equal to the dense path's and to finite differences. Small files: a
spatial RSSR four-bar forced onto the band for its samples' σ_min and its partial
gradient, and the 4-leg strandbeest (the arrowhead) for one sample point. A whole
evaluation on both paths is compared by ``benchmarks/bench_bodies.py`` (two compiles
of the evaluation are too slow for the suite)."""

import dataclasses
import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from strandbeest import strandbeest
from test_partial_gradient import RSSR

import linkopt
from linkopt._design.evaluation import alpha_minus, evaluate
from linkopt._design.partial import frozen_objective, partial_gradient
from linkopt._design.sampling import evaluate_point
from linkopt._engine import banded, jacobian
from linkopt._engine.constraints import fk_residual
from linkopt._engine.geometry import geometry, rest_state
from linkopt._engine.kinematics import solve_single
from linkopt._engine.singularity import f_sing_value


def _with_factor(mech, factor: str):
    return dataclasses.replace(
        mech, solver=dataclasses.replace(mech.solver, factor=factor)
    )


@pytest.fixture(scope="module")
def rssr():
    dense = linkopt.loads(RSSR)  # the programs of test_partial_gradient.py
    band = _with_factor(dense, "banded")
    assert not banded.serves(dense) and banded.serves(band)
    p = np.array([61.0])
    ev = jax.tree_util.tree_map(np.asarray, evaluate(dense, p))
    return dense, band, p, alpha_minus(dense), ev


def test_the_samples_sigma_min_on_the_band_equals_the_dense_evaluation(rssr):
    """Each sample's ``f_sing`` (both σ_min) on the band equals the dense
    evaluation's, at the IK and the adversarial samples."""
    _, band, p, _, ev = rssr
    geom = geometry(band, jnp.asarray(p))
    f_sing = jax.jit(jax.vmap(lambda s: f_sing_value(band, geom, s)))
    np.testing.assert_allclose(f_sing(ev.ik_states), ev.ik_f_sing, rtol=1e-8)
    np.testing.assert_allclose(f_sing(ev.adv_states), ev.adv_f_sing, rtol=1e-8)


def test_the_banded_partial_gradient_equals_the_dense_one_and_differences(rssr):
    dense, band, p, alpha, ev = rssr
    expected = np.asarray(partial_gradient(dense, p, ev, alpha))
    got = np.asarray(partial_gradient(band, p, ev, alpha))
    np.testing.assert_allclose(got, expected, rtol=1e-7)
    objective = jax.jit(
        functools.partial(frozen_objective, dense, evaluation=ev, alpha=alpha)
    )
    h = 1e-4
    fd = (objective(p + h) - objective(p - h)) / (2 * h)
    assert abs(float(fd)) > 1e-6
    np.testing.assert_allclose(got, [fd], rtol=1e-4)


@pytest.fixture(scope="module")
def walker():
    mech = linkopt.loads(strandbeest(4), "strandbeest.toml")
    assert banded.serves(mech)  # the arrowhead, by default
    return mech


def _point(mech, geom, motors, state):
    def objective(motors, state, ds_da, f_sing, d_f_sing):  # everything it is given
        return f_sing, ds_da.T @ d_f_sing, jnp.zeros((motors.size,) * 2)

    return evaluate_point(objective, mech, geom, motors, state)


def test_a_sample_point_on_the_arrowhead_equals_the_svd_and_differences(walker):
    """``f_sing`` of a sample point on the arrowhead against the SVD of the dense
    Jacobians, and ``ds/da`` against central differences of the forward solve
    (σ_min's gradient on the band against the dense one: ``tests/test_banded.py``)."""
    geom = geometry(walker)
    motors = jnp.asarray(linkopt.motor_values(walker, rest_state(walker))) + 0.3
    state = solve_single(walker, "fk", geom, motors, rest_state(walker)).state
    *_, ds_da, f_sing = jax.jit(_point, static_argnums=0)(walker, geom, motors, state)
    jac = np.asarray(jacobian.stacked_jacobians(walker, geom, state))
    exact = [np.linalg.svd(j, compute_uv=False)[-1] for j in jac]
    np.testing.assert_allclose(f_sing, np.sum(1.0 / np.asarray(exact)), rtol=1e-7)
    h = 1e-6
    ends = [solve_single(walker, "fk", geom, motors + d, state).state for d in (h, -h)]
    fd = (ends[0] - ends[1]) / (2 * h)
    assert ds_da.shape == (walker.state_size, 1)
    np.testing.assert_allclose(ds_da[:, 0], fd, atol=1e-6 * np.abs(fd).max())


def test_the_adjoint_multiplier_on_the_arrowhead_is_the_dense_one(walker):
    geom = geometry(walker)
    state = rest_state(walker)
    motors = jnp.asarray(linkopt.motor_values(walker, state))
    d_state = np.random.default_rng(0).standard_normal(state.shape)
    mu = banded.adjoint_multiplier(walker, geom, motors, state, d_state)
    jac = np.asarray(jacobian.state_jacobian(walker, geom, "fk", state))
    expected = jac @ np.linalg.solve(jac.T @ jac, d_state)
    np.testing.assert_allclose(mu, expected, atol=1e-8 * np.abs(expected).max())
    assert mu.shape == fk_residual(walker, geom, motors, state).shape


def test_singular_values_of_a_batch_on_the_arrowhead_are_the_svds(walker):
    """``linkopt.singular_values`` (the verification grid's and the CLI's σ_min) on
    the band: a batch of two solved states against the SVD of the dense Jacobians."""
    geom = geometry(walker)
    rest = rest_state(walker)
    motors = jnp.asarray(linkopt.motor_values(walker, rest))
    states = np.stack(
        [rest, solve_single(walker, "fk", geom, motors - 0.2, rest).state]
    )
    got = np.asarray(linkopt.singular_values(walker, states))
    for state, pair in zip(states, got, strict=True):
        jac = np.asarray(jacobian.stacked_jacobians(walker, geom, state))
        exact = [np.linalg.svd(j, compute_uv=False)[-1] for j in jac]
        np.testing.assert_allclose(pair, exact, rtol=1e-7)
