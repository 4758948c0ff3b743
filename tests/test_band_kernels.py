"""The block-band Cholesky of :mod:`linkopt._engine.band_factor` in the compiled kernels
(``band_factor``, ``band_solve``) against its plain-JAX scans (the kernels turned off
by making :func:`linkopt._engine.dense.kernels_serve` say no while a program is
traced) and against numpy's dense solve: values, batches, one factor for many
right-hand sides under ``vmap``, a failing pivot, derivatives and refused operands;
and the band's assembly from the rows' blocks (``band_normal``, and ``arrow_normal``
with hub bodies last) against the plain scatter adds of
:func:`linkopt._engine.banded.normal_equations`."""

import dataclasses
import tomllib

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from long_linkages import chain, ladder, ladder_cells
from strandbeest import strandbeest

import linkopt  # noqa: F401  (float64)
from linkopt._engine import band_factor, banded, dense
from linkopt._engine.geometry import geometry, rest_state
from linkopt._files.loader import build

pytestmark = pytest.mark.skipif(
    dense.TARGETS is None,
    reason="the compiled extension is not built here (linkopt._kernels)",
)

#: (block rows B, blocks a row w + 1)
SHAPES = [(1, 2), (6, 2), (9, 3), (25, 3), (4, 6)]


def _spd_band(bodies: int, w1: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """A symmetric positive definite ``H`` of ``bodies`` block rows whose blocks vanish
    more than ``w1 - 1`` places from the diagonal, dense and in band storage."""
    rng = np.random.default_rng(seed)
    n = 7 * bodies
    m = np.zeros((n, n))
    for i in range(bodies):
        for j in range(max(0, i - w1 + 1), i + 1):
            m[7 * i : 7 * i + 7, 7 * j : 7 * j + 7] = rng.standard_normal((7, 7))
    h = m @ m.T + 0.1 * np.eye(n)
    band = np.zeros((bodies, w1, 7, 7))
    for i in range(bodies):
        for k in range(min(w1, i + 1)):
            band[i, k] = h[7 * i : 7 * i + 7, 7 * (i - k) : 7 * (i - k) + 7]
    return h, band


def _routines():
    """The four routines jitted afresh (new functions: traced again, on whichever path
    :func:`dense.kernels_serve` now chooses)."""
    routines = {
        "factor": band_factor.factor,
        "forward": band_factor.forward,
        "backward": band_factor.backward,
        "cho_solve": band_factor.cho_solve,
    }
    return {name: jax.jit(_fresh(f)) for name, f in routines.items()}


def _fresh(f):
    return lambda *args: f(*args)


def _all(routines, band, damping, b):
    lower = routines["factor"](band, damping)
    return {
        "factor": lower,
        "forward": routines["forward"](lower, b),
        "backward": routines["backward"](lower, b),
        "cho_solve": routines["cho_solve"](lower, b),
    }


@pytest.mark.parametrize(("bodies", "w1"), SHAPES)
def test_the_kernels_are_the_scans_and_solve_the_dense_system(bodies, w1, monkeypatch):
    h, band = _spd_band(bodies, w1, seed=bodies + w1)
    b = np.random.default_rng(1).standard_normal((bodies, 7))
    damping = 1e-3
    kernel = _all(_routines(), jnp.asarray(band), damping, jnp.asarray(b))
    monkeypatch.setattr(dense, "kernels_serve", lambda *arrays: False)
    scans = _all(_routines(), jnp.asarray(band), damping, jnp.asarray(b))
    for name in kernel:
        scale = 1.0 + float(jnp.max(jnp.abs(scans[name])))
        assert float(jnp.max(jnp.abs(kernel[name] - scans[name]))) <= 1e-12 * scale, (
            name
        )
    dense_x = np.linalg.solve(h + damping * np.eye(7 * bodies), b.reshape(-1))
    assert np.allclose(np.asarray(kernel["cho_solve"]).reshape(-1), dense_x, atol=1e-10)
    lower = np.asarray(kernel["factor"])
    assert np.all(np.triu(lower[:, 0], 1) == 0.0)  # diagonal blocks lower triangular


def test_one_factor_serves_many_right_hand_sides_and_many_factors_one():
    h, band = _spd_band(12, 3, seed=3)
    rng = np.random.default_rng(2)
    columns = jnp.asarray(rng.standard_normal((5, 12, 7)))
    lower = band_factor.factor(jnp.asarray(band), 0.0)
    solved = jax.jit(jax.vmap(band_factor.cho_solve, in_axes=(None, 0)))(lower, columns)
    for c in range(5):
        one = band_factor.cho_solve(lower, columns[c])
        assert np.array_equal(np.asarray(solved[c]), np.asarray(one))
    # factors batched, one right-hand side; and factors x columns, nested
    bands = jnp.asarray(np.stack([band, 2.0 * band, 3.0 * band]))
    lowers = jax.jit(jax.vmap(band_factor.factor, in_axes=(0, None)))(bands, 1e-6)
    each = jax.jit(jax.vmap(band_factor.cho_solve, in_axes=(0, None)))(
        lowers, columns[0]
    )
    nested = jax.jit(
        jax.vmap(jax.vmap(band_factor.cho_solve, in_axes=(None, 0)), in_axes=(0, None))
    )(lowers, columns)
    for s, scale in enumerate((1.0, 2.0, 3.0)):
        matrix = scale * h + 1e-6 * np.eye(84)
        reference = np.linalg.solve(matrix, np.asarray(columns).reshape(5, -1).T).T
        assert np.allclose(np.asarray(each[s]).reshape(-1), reference[0], atol=1e-10)
        assert np.allclose(np.asarray(nested[s]).reshape(5, -1), reference, atol=1e-10)


@pytest.mark.parametrize("row", [0, 4, 8])
def test_a_failing_pivot_gives_nan_from_its_block_row_on(row, monkeypatch):
    _, band = _spd_band(9, 3, seed=5)
    band[row, 0] -= 100.0 * np.eye(7)  # indefinite from this block row on
    kernel = np.asarray(band_factor.factor(jnp.asarray(band), 0.0))
    monkeypatch.setattr(dense, "kernels_serve", lambda *arrays: False)
    scans = np.asarray(band_factor.factor(jnp.asarray(band), 0.0))
    for lower in (kernel, scans):
        failed = np.isnan(lower).any(axis=(1, 2, 3))
        assert not failed[:row].any() and failed[row:].all()
    assert np.allclose(kernel[:row], scans[:row], atol=1e-12)


def test_the_derivatives_are_the_scans(monkeypatch):
    _, band = _spd_band(5, 2, seed=7)
    band = jnp.asarray(band)
    rng = np.random.default_rng(3)
    tangent = jnp.asarray(rng.standard_normal(band.shape))
    b = jnp.asarray(rng.standard_normal((5, 7)))

    def solved(x):
        return band_factor.cho_solve(band_factor.factor(x, 1e-4), b)

    def derivatives():  # traced afresh: on the path kernels_serve now picks
        def both(x):
            forward = jax.jvp(solved, (x,), (tangent,))
            return forward, jax.grad(lambda y: jnp.sum(solved(y) ** 2))(x)

        return jax.jit(both)(band)

    kernel = derivatives()
    monkeypatch.setattr(dense, "kernels_serve", lambda *arrays: False)
    scans = derivatives()
    for got, want in zip(jax.tree.leaves(kernel), jax.tree.leaves(scans), strict=True):
        assert np.allclose(np.asarray(got), np.asarray(want), rtol=1e-9, atol=1e-11)
    # and the derivative is right: central differences of the solve
    step = 1e-6
    ahead = solved(band + step * tangent)
    behind = solved(band - step * tangent)
    assert np.allclose(
        np.asarray(kernel[0][1]), np.asarray(ahead - behind) / (2 * step), atol=1e-6
    )


def test_refused_operands_give_errors_not_crashes():
    _, band = _spd_band(4, 2, seed=9)
    lower = band_factor.factor(jnp.asarray(band), 0.0)
    with pytest.raises(Exception, match="b of shape"):
        dense.call_kernel(
            "band_solve", jnp.zeros((5, 7)), lower, jnp.zeros((5, 7)), mode=np.int32(2)
        ).block_until_ready()
    with pytest.raises(Exception, match="mode must be"):
        dense.call_kernel(
            "band_solve", jnp.zeros((4, 7)), lower, jnp.zeros((4, 7)), mode=np.int32(3)
        ).block_until_ready()
    with pytest.raises(Exception, match="band operand"):
        blocks = jnp.zeros((4, 2, 7, 6))
        dense.call_kernel(
            "band_factor", blocks, blocks, jnp.zeros(())
        ).block_until_ready()


def _long(kind: str, bodies: int):
    if kind == "walker":  # 4 legs on one crank: its ground and crank are hubs
        text = strandbeest(4)
    else:
        text = chain(bodies) if kind == "chain" else ladder(ladder_cells(bodies))
    mech = build(tomllib.loads(text), kind, check=False)
    return dataclasses.replace(
        mech, solver=dataclasses.replace(mech.solver, factor="banded")
    )


@pytest.mark.parametrize("kind", ["chain", "ladder", "walker"])
def test_the_band_assembly_kernel_is_the_scatter_adds(kind, monkeypatch):
    """``JᵀJ`` and ``JᵀC`` of a long linkage's rows assembled by ``band_normal`` (a
    walker's, whose hubs go last: ``arrow_normal``) equal the plain scatter adds, and
    so do their derivatives in the state."""
    mech = _long(kind, 24)
    geom = geometry(mech)
    assert banded.layout(mech, geom, "fk").hubs == (2 if kind == "walker" else 0)
    rng = np.random.default_rng(4)
    state = jnp.asarray(rest_state(mech) + 0.01 * rng.normal(size=mech.state_size))
    tangent = jnp.asarray(rng.normal(size=mech.state_size))
    values = jnp.full(mech.num_motors, 0.1)

    def assembled():  # traced afresh: on the path kernels_serve now picks
        def f(s):
            return banded.normal_equations.__wrapped__(mech, geom, "fk", values, s)

        return jax.jit(lambda s, t: jax.jvp(f, (s,), (t,)))(state, tangent)

    kernel = assembled()
    monkeypatch.setattr(dense, "kernels_serve", lambda *arrays: False)
    plain = assembled()
    for got, want in zip(jax.tree.leaves(kernel), jax.tree.leaves(plain), strict=True):
        scale = 1.0 + float(jnp.max(jnp.abs(want)))
        assert float(jnp.max(jnp.abs(got - want))) <= 1e-13 * scale
    for part in jax.tree.leaves(kernel[0][1]):  # a band (border, corner), not zeros
        assert float(jnp.max(jnp.abs(part))) > 0


def test_the_band_assembly_refuses_pairs_outside_the_band():
    rows, residual = jnp.ones((2, 14)), jnp.ones(2)
    shapes = (
        jax.ShapeDtypeStruct((4, 2, 7, 7), rows.dtype),
        jax.ShapeDtypeStruct((4, 7), rows.dtype),
    )
    for pairs, message in (
        ([0, 1, 0, 2], "outside the band"),
        ([0, 4, 1, 1], "out of range"),
    ):
        with pytest.raises(Exception, match=message):
            jax.block_until_ready(
                dense.call_kernel(
                    "band_normal",
                    shapes,
                    rows,
                    residual,
                    pairs=np.asarray(pairs, np.int32),
                )
            )
