"""Plain-JAX dense linear algebra (linkopt._engine.dense) against numpy/scipy: values,
vmapped batches, and derivatives against finite differences."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import scipy.linalg

import linkopt  # noqa: F401  (float64)
from linkopt._engine import dense, dense_lu, eigh

SIZES = [1, 2, 3, 7, 35, 80]


def spd(n, seed=0):
    m = np.random.default_rng(seed).standard_normal((n, n))
    return m @ m.T + n * np.eye(n)


def general(n, seed=0):
    return np.random.default_rng(seed).standard_normal((n, n)) + 0.1 * np.eye(n)


@pytest.mark.parametrize("n", SIZES)
def test_cholesky_and_triangular_solves_match_lapack(n):
    a = spd(n, n)
    b = np.random.default_rng(1).standard_normal((n, 4))
    lower = np.asarray(jax.jit(dense.cholesky)(a))
    np.testing.assert_allclose(lower, np.linalg.cholesky(a), atol=1e-13 * n)
    assert np.all(np.triu(lower, 1) == 0)
    np.testing.assert_allclose(
        dense.solve_lower(lower, b),
        scipy.linalg.solve_triangular(lower, b, lower=True),
        rtol=1e-12,
        atol=1e-12,
    )
    np.testing.assert_allclose(
        dense.solve_lower_transpose(lower, b),
        scipy.linalg.solve_triangular(lower.T, b, lower=False),
        rtol=1e-12,
        atol=1e-12,
    )
    np.testing.assert_allclose(
        dense.solve_upper(lower.T, b[:, 0]),
        scipy.linalg.solve_triangular(lower.T, b[:, 0]),
        rtol=1e-12,
        atol=1e-12,
    )
    exact = np.linalg.solve(a, b)
    np.testing.assert_allclose(dense.cho_solve(lower, b), exact, rtol=1e-11, atol=1e-13)
    np.testing.assert_allclose(dense.solve_spd(a, b), exact, rtol=1e-11, atol=1e-13)
    inverse = np.asarray(dense.lower_inverse(lower))
    np.testing.assert_allclose(inverse @ lower, np.eye(n), atol=1e-13)


@pytest.mark.parametrize("n", [*SIZES, 98])
def test_damped_solve_is_the_cho_solve_of_the_damped_matrix(n):
    """The same numbers as :func:`dense.cho_solve` of the :func:`dense.cholesky` of
    ``a + d I``, vmapped (the Levenberg–Marquardt step); alone too, with the kernels;
    98 is above the fused kernel's order limit."""
    rng = np.random.default_rng(n)
    a = jnp.asarray(np.stack([spd(n, n), spd(n, n + 1), spd(n, n + 2)]))
    d = jnp.asarray([0.0, 1e-12, 3.5])
    b = jnp.asarray(rng.standard_normal((3, n)))

    def separate(a, d, b):
        return dense.cho_solve(dense.cholesky(a + d * jnp.eye(n)), b)

    x = jax.jit(jax.vmap(dense.damped_solve))(a, d, b)
    np.testing.assert_array_equal(x, jax.jit(jax.vmap(separate))(a, d, b))
    single = jax.jit(dense.damped_solve)(a[1], d[1], b[1])
    if dense.TARGETS is not None:  # the kernels: bitwise; XLA's loops vmapped: not
        np.testing.assert_array_equal(x[1], single)
    np.testing.assert_allclose(x[1], single, rtol=1e-12, atol=1e-15)
    exact = np.linalg.solve(a + d[:, None, None] * np.eye(n), b[..., None])[..., 0]
    np.testing.assert_allclose(x, exact, rtol=1e-10, atol=1e-13)


def test_damped_solve_differentiates_as_the_separate_calls():
    """Its derivative (the plain code's, through the factorisation) is that of
    cho_solve(cholesky(a + d I), b) in all three arguments."""
    a, b = jnp.asarray(spd(7, 3)), jnp.asarray(np.random.default_rng(3).random(7))

    def separate(a, d, b):
        return dense.cho_solve(dense.cholesky(a + d * jnp.eye(7)), b)

    for arg in range(3):
        got = jax.jacfwd(dense.damped_solve, argnums=arg)(a, 0.5, b)
        np.testing.assert_allclose(
            got, jax.jacfwd(separate, argnums=arg)(a, 0.5, b), rtol=1e-12, atol=1e-15
        )


@pytest.mark.parametrize("n", SIZES)
def test_lu_solve_and_det_match_lapack(n):
    a = general(n, n)
    b = np.random.default_rng(2).standard_normal(n)
    lu, perm, sign = dense_lu.lu_factor(a)
    p, lower, upper = scipy.linalg.lu(a)  # a = p @ lower @ upper
    np.testing.assert_allclose(np.asarray(a)[np.asarray(perm)], p.T @ a)
    np.testing.assert_allclose(np.triu(lu), upper, atol=1e-12 * n)
    scale = np.abs(np.linalg.solve(a, b)).max()
    np.testing.assert_allclose(
        dense_lu.solve(a, b), np.linalg.solve(a, b), atol=1e-12 * scale
    )
    np.testing.assert_allclose(dense_lu.det(a), np.linalg.det(a), rtol=1e-11)
    assert float(sign) == np.sign(np.linalg.det(p))


def test_non_spd_and_singular_inputs_are_documented_values():
    assert np.all(np.isnan(dense.cholesky(-np.eye(3))[np.tril_indices(3)]))
    assert np.all(np.isnan(dense.solve_spd(np.diag([1.0, -1.0, 1.0]), np.ones(3))))
    singular = np.array([[1.0, 2.0, 0.5, 1.0]] * 2 + [[0.0, 1.0, 3.0, 1.0]] * 2)
    assert float(dense_lu.det(singular)) == 0.0
    assert float(dense_lu.det(np.ones((3, 3)))) == 0.0


@pytest.mark.parametrize("k", [1, 2, 3, 6])
def test_symmetric_eigh_matches_lapack(k):
    m = np.random.default_rng(k).standard_normal((k, k))
    a = m + m.T
    w, v = jax.jit(eigh.symmetric_eigh)(a)
    np.testing.assert_allclose(w, np.linalg.eigvalsh(a), atol=1e-13 * np.abs(a).max())
    np.testing.assert_allclose(np.asarray(a) @ v, v * w, atol=1e-12)
    np.testing.assert_allclose(v.T @ v, np.eye(k), atol=1e-13)


def test_symmetric_eigh_of_clustered_and_diagonal_spectra():
    q = np.linalg.qr(np.random.default_rng(3).standard_normal((6, 6)))[0]
    w0 = np.array([1.0, 1.007, 3.0, 3.0, 10.0, 1e4])  # 0.7 % gap and a double value
    w, v = eigh.symmetric_eigh((q * w0) @ q.T)
    np.testing.assert_allclose(w, w0, rtol=1e-12, atol=1e-11)
    assert abs(abs(float(v[:, 0] @ q[:, 0])) - 1.0) < 1e-10
    w, v = eigh.symmetric_eigh(np.diag([3.0, 1.0, 2.0]))
    np.testing.assert_array_equal(w, [1.0, 2.0, 3.0])
    np.testing.assert_array_equal(np.abs(v), np.eye(3)[:, [1, 2, 0]])


def test_routines_vmap_over_a_batch():
    a = np.stack([spd(12, s) for s in range(5)])
    g = np.stack([general(12, s) for s in range(5)])
    b = np.random.default_rng(4).standard_normal((5, 12))
    np.testing.assert_allclose(
        jax.jit(jax.vmap(dense.solve_spd))(a, b),
        np.linalg.solve(a, b[..., None])[..., 0],
    )
    np.testing.assert_allclose(
        jax.vmap(dense_lu.solve)(g, b),
        np.linalg.solve(g, b[..., None])[..., 0],
        rtol=1e-10,
        atol=1e-12,
    )
    np.testing.assert_allclose(jax.vmap(dense_lu.det)(g), np.linalg.det(g), rtol=1e-11)
    w, _ = jax.vmap(eigh.symmetric_eigh)(a[:, :6, :6])
    np.testing.assert_allclose(w, np.linalg.eigvalsh(a[:, :6, :6]), rtol=1e-12)


def _fd_check(fn, x, direction, rtol):
    """Forward- and reverse-mode derivatives of a scalar ``fn`` against central
    differences along ``direction``."""
    h = 1e-6
    fd = (fn(x + h * direction) - fn(x - h * direction)) / (2 * h)
    _, jvp = jax.jvp(fn, (x,), (direction,))
    grad = jax.grad(fn)(x)
    np.testing.assert_allclose(jvp, fd, rtol=rtol)
    np.testing.assert_allclose(jnp.vdot(grad, direction), fd, rtol=rtol)


@pytest.mark.parametrize("name", ["solve_spd", "solve"])
def test_solve_derivatives_in_matrix_and_rhs(name):
    n = 9
    a0 = spd(n, 5) if name == "solve_spd" else general(n, 5)
    b0 = np.random.default_rng(6).standard_normal(n)
    w = np.random.default_rng(7).standard_normal(n)
    solver = dense.solve_spd if name == "solve_spd" else dense_lu.solve
    d_a = np.random.default_rng(8).standard_normal((n, n))
    d_a = d_a + d_a.T if name == "solve_spd" else d_a
    _fd_check(lambda a: w @ solver(a, b0), jnp.asarray(a0), d_a, 1e-6)
    _fd_check(lambda b: w @ solver(a0, b), jnp.asarray(b0), np.ones(n), 1e-8)
    # vmapped gradients, as the sensitivities and partial gradients take them
    grads = jax.vmap(jax.grad(lambda b: w @ solver(a0, b)))(np.stack([b0, 2 * b0]))
    np.testing.assert_allclose(grads[0], np.linalg.solve(np.asarray(a0).T, w))


def test_det_derivative():
    a0 = general(5, 9)
    direction = np.random.default_rng(10).standard_normal((5, 5))
    _fd_check(dense_lu.det, jnp.asarray(a0), direction, 1e-7)
    _fd_check(dense_lu.det, jnp.asarray(a0[:3, :3]), direction[:3, :3], 1e-8)
