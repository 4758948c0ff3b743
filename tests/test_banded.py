"""The banded normal equations (:mod:`linkopt._engine.banded`): the band's order, its
factor and products against dense linear algebra, and the FK/BK solves and their
implicit derivatives on the banded path against the dense path and finite
differences."""

import dataclasses
import tomllib
from functools import partial

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from conftest import MECHANISMS, ROOT
from long_linkages import chain, ladder

import linkopt
from linkopt._engine import banded, banded_sigma, jacobian, singularity
from linkopt._engine.geometry import geometry, rest_state
from linkopt._files.loader import build

FILES = [
    MECHANISMS / "five_bar.toml",
    MECHANISMS / "jansen_1dof.toml",
    ROOT / "tests/data/all_families.toml",
]


def _with_factor(mech, factor: str):
    return dataclasses.replace(
        mech, solver=dataclasses.replace(mech.solver, factor=factor)
    )


def _dense_from_band(band: np.ndarray) -> np.ndarray:
    nb, w1 = band.shape[:2]
    full = np.zeros((nb, 7, nb, 7))
    for i in range(nb):
        for k in range(min(w1, i + 1)):
            full[i, :, i - k] = band[i, k]
            full[i - k, :, i] = band[i, k].T
    return full.reshape(7 * nb, 7 * nb)


def _random_band(nb: int, w: int, seed: int) -> np.ndarray:
    """``JᵀJ + I`` in band storage for a random ``J`` whose rows touch bodies at most
    ``w`` apart."""
    rng = np.random.default_rng(seed)
    band = np.zeros((nb, w + 1, 7, 7))
    for i in range(nb):
        for k in range(min(w, i) + 1):
            rows = rng.normal(size=(3, 14))
            a, b = rows[:, :7], rows[:, 7:]  # bodies i and i - k
            band[i, 0] += a.T @ a + (np.eye(7) if k == 0 else 0.0)
            if k:
                band[i - k, 0] += b.T @ b
                band[i, k] += a.T @ b
    return band


@pytest.mark.parametrize("nb, w", [(1, 1), (6, 1), (9, 3), (20, 2)])
def test_the_band_factor_solves_and_multiplies_as_the_dense_matrix(nb, w):
    band = _random_band(nb, w, seed=nb)
    full = _dense_from_band(band)
    rhs = np.random.default_rng(1).normal(size=(nb, 7))
    for damping in (0.0, 0.5):
        solved = banded.damped_solve(jnp.asarray(band), damping, jnp.asarray(rhs))
        expected = np.linalg.solve(full + damping * np.eye(7 * nb), rhs.reshape(-1))
        np.testing.assert_allclose(np.asarray(solved).reshape(-1), expected, atol=1e-10)
    lower = np.asarray(banded.factor(jnp.asarray(band), 0.0))
    np.testing.assert_allclose(
        _lower_from_band(lower), np.linalg.cholesky(full), atol=1e-10
    )
    product = banded.matvec(jnp.asarray(band), jnp.asarray(rhs))
    np.testing.assert_allclose(
        np.asarray(product).reshape(-1), full @ rhs.reshape(-1), atol=1e-10
    )


def _lower_from_band(lower: np.ndarray) -> np.ndarray:
    nb, w1 = lower.shape[:2]
    full = np.zeros((nb, 7, nb, 7))
    for i in range(nb):
        for k in range(min(w1, i + 1)):
            full[i, :, i - k] = lower[i, k]
    return full.reshape(7 * nb, 7 * nb)


def test_an_indefinite_band_gives_nan_not_an_answer():
    band = _random_band(5, 1, seed=3)
    band[2, 0] -= 100.0 * np.eye(7)
    solved = banded.damped_solve(jnp.asarray(band), 0.0, jnp.ones((5, 7)))
    assert np.isnan(np.asarray(solved)).any()


def test_the_order_of_a_shuffled_chain_is_a_band_of_width_one():
    rng = np.random.default_rng(0)
    labels = rng.permutation(50)
    pairs = np.stack([labels[:-1], labels[1:]], axis=1)
    layout = banded.body_order(50, pairs)
    assert layout.width == 1
    assert sorted(layout.order) == list(range(50))
    assert np.array_equal(layout.position[layout.order], np.arange(50))


@pytest.mark.parametrize("kind", ["fk", "bk"])
@pytest.mark.parametrize("path", FILES, ids=lambda p: p.stem)
def test_banded_normal_equations_equal_the_dense_ones(path, kind):
    mech = build(tomllib.loads(path.read_text()), str(path), check=False)
    geom = geometry(mech)
    state = rest_state(mech) + 0.01 * np.random.default_rng(0).normal(
        size=mech.state_size
    )
    count = mech.num_motors if kind == "fk" else mech.num_outputs
    values = jnp.full(count, 0.1)
    residual, hessian, gradient = jacobian.normal_equations(
        mech, geom, kind, values, state
    )
    residual_b, band, gradient_b = banded.normal_equations(
        mech, geom, kind, values, state
    )
    layout = banded.layout(mech, geom, kind)
    order = (7 * layout.order[:, None] + np.arange(7)).reshape(-1)
    np.testing.assert_allclose(residual_b, residual, rtol=0, atol=1e-14)
    np.testing.assert_allclose(
        _dense_from_band(np.asarray(band)),
        np.asarray(hessian)[np.ix_(order, order)],
        atol=1e-12,
    )
    np.testing.assert_allclose(
        np.asarray(gradient_b).reshape(-1), np.asarray(gradient)[order], atol=1e-12
    )


def _small_mechanisms():
    return [
        linkopt.load(MECHANISMS / "five_bar.toml"),
        linkopt.load(MECHANISMS / "jansen_1dof.toml"),
        linkopt.loads(ladder(3), "ladder.toml"),
    ]


@pytest.mark.parametrize("index", range(3), ids=["five_bar", "jansen", "ladder"])
def test_fk_and_bk_on_the_banded_path_equal_the_dense_path(index):
    mech = _small_mechanisms()[index]
    dense, band = _with_factor(mech, "dense"), _with_factor(mech, "banded")
    assert not banded.serves(dense) and banded.serves(band)
    rng = np.random.default_rng(index)
    motors = linkopt.motor_values(mech, rest_state(mech))
    rows = motors + rng.uniform(-0.2, 0.2, size=(3, mech.num_motors))
    expected = linkopt.solve_fk(dense, rows)
    got = linkopt.solve_fk(band, rows)
    assert np.all(np.asarray(expected.converged))
    np.testing.assert_array_equal(np.asarray(got.converged), expected.converged)
    np.testing.assert_allclose(got.state, expected.state, atol=1e-10)
    outputs = linkopt.output_values(mech, np.asarray(expected.state))
    back = linkopt.solve_bk(band, outputs, start=rest_state(mech))
    again = linkopt.solve_bk(dense, outputs, start=rest_state(mech))
    np.testing.assert_allclose(back.state, again.state, atol=1e-10)


def test_a_path_on_the_band_equals_the_dense_path():
    """A path solve walks each row from the last one: the band's walk (nested loops,
    a fresh prediction per step) and the dense one (one loop, each row starting from
    the normal equations the last row ended with) reach the same states."""
    mech = _small_mechanisms()[0]
    dense, band = _with_factor(mech, "dense"), _with_factor(mech, "banded")
    motors = np.asarray(linkopt.motor_values(mech, rest_state(mech)))
    rows = motors + np.linspace(0.0, 1.0, 6)[:, None] * np.array([0.5, -0.3])
    expected = linkopt.solve_fk_path(dense, rows)
    got = linkopt.solve_fk_path(band, rows)
    assert np.all(np.asarray(expected.converged))
    np.testing.assert_array_equal(np.asarray(got.converged), expected.converged)
    np.testing.assert_allclose(got.state, expected.state, atol=1e-10)


def test_banded_sensitivities_match_finite_differences_and_the_dense_path():
    mech = _with_factor(linkopt.load(MECHANISMS / "five_bar.toml"), "banded")
    dense = _with_factor(mech, "dense")
    # solved in a batch of three rows, the block program the FK test above compiles
    rows = np.array([[0.1, -0.1], [0.05, -0.05], [0.1, 0.1]])
    state = np.asarray(linkopt.solve_fk(mech, rows).state)[0]
    p0 = np.asarray(mech.design.p0)
    got = np.asarray(linkopt.sensitivity(mech, state, "design"))
    np.testing.assert_allclose(
        got, linkopt.sensitivity(dense, state, "design"), atol=1e-10
    )
    motors = linkopt.motor_values(mech, state)
    step = 1e-6
    for k in range(p0.size):
        shift = np.eye(p0.size)[k] * step
        up = linkopt.solve_fk(mech, motors, start=state, design=p0 + shift).state
        down = linkopt.solve_fk(mech, motors, start=state, design=p0 - shift).state
        fd = (np.asarray(up) - np.asarray(down)) / (2 * step)
        np.testing.assert_allclose(got[:, k], fd, atol=1e-6)


def test_reverse_mode_through_a_banded_solve_equals_the_dense_one():
    mech = linkopt.load(MECHANISMS / "jansen_1dof.toml")
    start = rest_state(mech)
    motors = linkopt.motor_values(mech, start) + 0.1

    def loss(m, design):
        state = linkopt.solve_fk(m, motors, start=start, design=design).state
        return jnp.sum(jnp.sin(state))

    p0 = jnp.asarray(mech.design.p0)
    dense = jax.grad(loss, argnums=1)(_with_factor(mech, "dense"), p0)
    band = jax.grad(loss, argnums=1)(_with_factor(mech, "banded"), p0)
    assert np.all(np.isfinite(np.asarray(band)))
    np.testing.assert_allclose(band, dense, atol=1e-10)


def test_a_long_chain_takes_the_banded_path_and_closes():
    """Above ``MIN_BODIES`` the default is banded, and the solve closes the chain's
    joints to the tolerance."""
    mech = linkopt.loads(chain(banded.MIN_BODIES), "chain.toml")
    assert banded.serves(mech)
    rows = np.random.default_rng(0).uniform(-0.2, 0.2, size=(2, mech.num_motors))
    solution = linkopt.solve_fk(mech, rows)
    assert np.all(np.asarray(solution.converged))
    assert float(np.max(solution.residual)) <= mech.solver.tolerance
    np.testing.assert_allclose(
        linkopt.motor_values(mech, np.asarray(solution.state)), rows, atol=1e-9
    )


def test_a_hub_joined_to_every_body_goes_last_and_keeps_the_band_narrow():
    """A body joined to every other (a walker's ground and crank) would make the band
    as wide as the mechanism; numbered last (the arrowhead), it leaves the rest a band
    of width one, and the default takes it."""
    mech = linkopt.loads(chain(2 * banded.MIN_BODIES), "chain.toml")
    count = mech.num_bodies
    star = np.stack([np.zeros(count - 1, dtype=int), np.arange(1, count)], axis=1)
    layout = banded.body_order(count, star)
    assert layout.hubs == 1 and layout.order[-1] == 0 and layout.width == 1
    assert banded.body_order(count, mech.joint_bodies).hubs == 0
    assert banded.serves(mech)
    assert banded.serves(dataclasses.replace(mech, joint_bodies=star))


@pytest.mark.parametrize("index", range(3), ids=["five_bar", "jansen", "ladder"])
def test_sigma_min_on_the_band_equals_the_dense_one_and_its_gradient(index):
    check_band_sigma_min(_small_mechanisms()[index])


def check_band_sigma_min(mech):
    """σ_min on the band's storage (band or arrowhead) equals the SVD's, and its
    ``f_sing`` value and gradient the dense path's (``tests/test_arrowhead.py`` too)."""
    geom = geometry(mech)
    state = rest_state(mech)

    def f_sing(sigmas, s):
        return jnp.sum(1.0 / sigmas(mech, geom, s))

    def dense_sigmas(m, g, s):  # the dense Jacobians whatever the factor setting
        return singularity.sigmas_of(singularity.stacked_jacobians(m, g, s))

    def f_sing_and_sigmas(s):  # the band's σ_min from its gradient's program
        sigmas = banded_sigma.sigma_min_pair(mech, geom, s)
        return jnp.sum(1.0 / sigmas), sigmas

    dense = jax.jit(jax.value_and_grad(partial(f_sing, dense_sigmas)))
    band = jax.jit(jax.value_and_grad(f_sing_and_sigmas, has_aux=True))
    (value, grad), ((value_b, sigmas), grad_b) = dense(state), band(state)
    jac = np.asarray(jacobian.stacked_jacobians(mech, geom, state))
    exact = [np.linalg.svd(j, compute_uv=False)[-1] for j in jac]
    np.testing.assert_allclose(sigmas, exact, rtol=1e-7)  # both iterate 6 sweeps
    np.testing.assert_allclose(value_b, value, rtol=1e-7)
    np.testing.assert_allclose(grad_b, grad, atol=5e-4 * np.abs(grad).max())
