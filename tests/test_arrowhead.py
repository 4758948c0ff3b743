"""The arrowhead order (:mod:`linkopt._engine.body_order`, hubs last) and its factor
(:mod:`linkopt._engine.arrowhead`) against dense linear algebra, and a strandbeest's
FK/BK solves, sensitivities and σ_min on it against the dense path, finite
differences and the SVD; the shipped ``strandbeest_12.toml`` is the generator's."""

import dataclasses

import jax.numpy as jnp
import numpy as np
import pytest
from conftest import MECHANISMS
from long_linkages import chain, ladder
from strandbeest import strandbeest
from test_banded import check_band_sigma_min

import linkopt
from linkopt._engine import arrowhead, banded, jacobian
from linkopt._engine.body_order import body_order
from linkopt._engine.geometry import geometry, rest_state

LEGS = 4  # the smallest walker whose ground and crank are hubs (9 neighbours each)


def _with_factor(mech, factor: str):
    return dataclasses.replace(
        mech, solver=dataclasses.replace(mech.solver, factor=factor)
    )


@pytest.fixture(scope="module")
def walker():
    return linkopt.loads(strandbeest(LEGS), "strandbeest.toml")


def _random_arrow(n: int, w: int, h: int, seed: int) -> np.ndarray:
    """``JᵀJ + I`` (dense, ``7(n + h)`` square) for a random ``J`` whose rows touch
    two bodies at most ``w`` apart among the first ``n``, or any body and a hub."""
    rng = np.random.default_rng(seed)
    nb = n + h
    full = np.eye(7 * nb)
    pairs = [(i, i - k) for i in range(n) for k in range(1, min(w, i) + 1)]
    pairs += [(n + j, i) for j in range(h) for i in range(nb) if i != n + j]
    for a, b in pairs:
        rows = np.zeros((3, 7 * nb))
        rows[:, 7 * a : 7 * a + 7] = rng.normal(size=(3, 7))
        rows[:, 7 * b : 7 * b + 7] = rng.normal(size=(3, 7))
        full += rows.T @ rows
    return full


def _arrow_from_dense(full: np.ndarray, n: int, w: int, h: int) -> arrowhead.Arrow:
    blocks = full.reshape(n + h, 7, n + h, 7).transpose(0, 2, 1, 3)
    band = np.zeros((n, w + 1, 7, 7))
    for i in range(n):
        for k in range(min(w, i) + 1):
            band[i, k] = blocks[i, i - k]
    border = np.stack([blocks[n:, i] for i in range(n)])  # border[i, j] = H[n + j, i]
    return arrowhead.Arrow(*map(jnp.asarray, (band, border, blocks[n:, n:])))


def _dense_from_arrow(arrow: arrowhead.Arrow) -> np.ndarray:
    band, border, corner = (np.asarray(a) for a in arrow)
    n, h = border.shape[:2]
    blocks = np.zeros((n + h, n + h, 7, 7))
    for i in range(n):
        for k in range(min(band.shape[1], i + 1)):
            blocks[i, i - k] = band[i, k]
            blocks[i - k, i] = band[i, k].T
        for j in range(h):
            blocks[n + j, i] = border[i, j]
            blocks[i, n + j] = border[i, j].T
    blocks[n:, n:] = corner
    return blocks.transpose(0, 2, 1, 3).reshape(7 * (n + h), 7 * (n + h))


@pytest.mark.parametrize("n, w, h", [(1, 1, 1), (12, 1, 2), (9, 3, 3)])
def test_the_arrowhead_factor_solves_and_multiplies_as_the_dense_matrix(n, w, h):
    full = _random_arrow(n, w, h, seed=n + h)
    arrow = _arrow_from_dense(full, n, w, h)
    np.testing.assert_array_equal(_dense_from_arrow(arrow), full)
    rhs = np.random.default_rng(2).normal(size=(n + h, 7))
    for damping in (0.0, 0.5):
        solved = banded.damped_solve(arrow, damping, jnp.asarray(rhs))
        expected = np.linalg.solve(full + damping * np.eye(full.shape[0]), rhs.ravel())
        np.testing.assert_allclose(np.asarray(solved).ravel(), expected, atol=1e-10)
    product = banded.matvec(arrow, jnp.asarray(rhs))
    np.testing.assert_allclose(
        np.asarray(product).ravel(), full @ rhs.ravel(), atol=1e-10
    )
    assert float(banded.trace(arrow)) == pytest.approx(np.trace(full), rel=1e-14)
    assert banded.size(arrow) == n + h


def test_an_indefinite_hub_block_gives_nan_not_an_answer():
    full = _random_arrow(6, 1, 2, seed=0)
    full[-7:, -7:] -= 1e4 * np.eye(7)
    arrow = _arrow_from_dense(full, 6, 1, 2)
    assert np.isnan(np.asarray(banded.damped_solve(arrow, 0.0, jnp.ones((8, 7))))).any()


def _pairs(mech) -> np.ndarray:
    pairs = np.concatenate([mech.joint_bodies, mech.output_table.bodies])
    return pairs[np.all(pairs >= 0, axis=1)]


def test_the_ground_and_crank_of_a_walker_go_last_and_the_legs_band_narrowly(walker):
    layout = body_order(walker.num_bodies, _pairs(walker))
    assert layout.hubs == 2
    hubs = {walker.body_names.index("ground"), walker.body_names.index("crank")}
    assert set(layout.order[-2:]) == hubs
    assert layout.width <= 2
    assert sorted(layout.order) == list(range(walker.num_bodies))
    assert walker.num_bodies >= banded.MIN_BODIES
    assert banded.serves(walker)  # "auto": the arrowhead's band is narrow


@pytest.mark.parametrize("text", [chain(60), ladder(8)], ids=["chain", "ladder"])
def test_chains_and_ladders_have_no_hubs(text):
    mech = linkopt.loads(text, "long.toml")
    assert body_order(mech.num_bodies, _pairs(mech)).hubs == 0


@pytest.mark.parametrize("kind", ["fk", "bk"])
def test_arrowhead_normal_equations_equal_the_dense_ones(walker, kind):
    geom = geometry(walker)
    state = rest_state(walker) + 0.01 * np.random.default_rng(0).normal(
        size=walker.state_size
    )
    values = jnp.full(1, 0.1)
    residual, hessian, gradient = jacobian.normal_equations(
        walker, geom, kind, values, state
    )
    residual_a, arrow, gradient_a = banded.normal_equations(
        walker, geom, kind, values, state
    )
    assert isinstance(arrow, arrowhead.Arrow)
    layout = banded.layout(walker, geom, kind)
    order = (7 * layout.order[:, None] + np.arange(7)).reshape(-1)
    np.testing.assert_allclose(residual_a, residual, rtol=0, atol=1e-14)
    np.testing.assert_allclose(
        _dense_from_arrow(arrow), np.asarray(hessian)[np.ix_(order, order)], atol=1e-12
    )
    np.testing.assert_allclose(
        np.asarray(gradient_a).ravel(), np.asarray(gradient)[order], atol=1e-12
    )


def test_fk_and_bk_on_the_arrowhead_equal_the_dense_path(walker):
    dense, band = _with_factor(walker, "dense"), _with_factor(walker, "banded")
    motors = linkopt.motor_values(walker, rest_state(walker))
    rows = motors + np.array([[0.3], [-0.4], [1.0]])
    expected = linkopt.solve_fk(dense, rows)
    got = linkopt.solve_fk(band, rows)
    assert np.all(np.asarray(expected.converged))
    np.testing.assert_array_equal(np.asarray(got.converged), expected.converged)
    np.testing.assert_allclose(got.state, expected.state, atol=1e-10)
    outputs = linkopt.output_values(walker, np.asarray(expected.state))
    back = linkopt.solve_bk(band, outputs, start=rest_state(walker))
    again = linkopt.solve_bk(dense, outputs, start=rest_state(walker))
    assert np.all(np.asarray(back.converged))
    np.testing.assert_allclose(back.state, again.state, atol=1e-10)


def test_arrowhead_sensitivities_match_finite_differences_and_the_dense_path(walker):
    mech = _with_factor(walker, "banded")
    start = rest_state(mech)
    motors = linkopt.motor_values(mech, start) + 0.2
    state = np.asarray(linkopt.solve_fk(mech, motors, start=start).state)
    p0 = np.asarray(mech.design.p0)
    got = np.asarray(linkopt.sensitivity(mech, state, "design"))
    dense = linkopt.sensitivity(_with_factor(walker, "dense"), state, "design")
    np.testing.assert_allclose(got, dense, atol=1e-10)
    # the solves converged far below the sensitivity's own error: FD error ~1e-11
    tight = dataclasses.replace(
        mech, solver=dataclasses.replace(mech.solver, tolerance=1e-15)
    )
    step = 1e-4
    for k in range(p0.size):
        shift = np.eye(p0.size)[k] * step
        up = linkopt.solve_fk(tight, motors, start=state, design=p0 + shift).state
        down = linkopt.solve_fk(tight, motors, start=state, design=p0 - shift).state
        fd = (np.asarray(up) - np.asarray(down)) / (2 * step)
        np.testing.assert_allclose(got[:, k], fd, atol=1e-9)


def test_sigma_min_on_the_arrowhead_equals_the_svd_and_the_dense_gradient(walker):
    check_band_sigma_min(walker)


def test_the_shipped_strandbeest_is_the_generated_one_and_takes_the_arrowhead():
    path = MECHANISMS / "strandbeest_12.toml"
    assert path.read_text().endswith(strandbeest(12))
    mech = linkopt.load(path)
    assert mech.num_bodies == 2 + 12 * 6
    assert banded.serves(mech)
    layout = body_order(mech.num_bodies, _pairs(mech))
    assert layout.hubs == 2 and layout.width <= 2
