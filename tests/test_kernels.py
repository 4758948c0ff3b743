"""The compiled kernels (linkopt._kernels): the extension's capsules, LINKOPT_KERNELS=0,
a missing or broken extension, and the XLA FFI handlers called directly through
jax.ffi.ffi_call against numpy (values, batches, vmap, a failing pivot, refused
operands)."""

import importlib.util
import subprocess
import sys

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import linkopt  # noqa: F401  (float64)
import linkopt._kernels as kernels
from linkopt._engine import dense

EXTENSION = "linkopt._kernels._dense"
BUILT = importlib.util.find_spec(EXTENSION) is not None
WHY_SKIPPED = f"{EXTENSION} is not built (linkopt installed without a C++ compiler?)"
needs_extension = pytest.mark.skipif(not BUILT, reason=WHY_SKIPPED)
SIZES = [1, 7, 35, 98]
#: the largest order of the damped solve (and of the two-matrix paths, dense.cc)
DAMPED_MAX_N = 160
#: leading (batch) dimensions of the operands
BATCHES = [(), (3,), (2, 2)]
#: names under which this file registers the handlers (not linkopt's own names)
PREFIX = "linkopt_test_kernels_"
_registered = False


@pytest.fixture(autouse=True)
def _kernels_on(monkeypatch):
    monkeypatch.delenv(kernels.ENVIRONMENT, raising=False)


@pytest.fixture
def ffi():
    """The handlers registered with XLA (once per process), the extension being
    built."""
    global _registered
    if not BUILT:
        pytest.skip(WHY_SKIPPED)
    capsules = kernels.handlers()
    assert capsules is not None, kernels.reason
    if not _registered:
        for name, capsule in capsules.items():
            jax.ffi.register_ffi_target(PREFIX + name, capsule, platform="cpu")
        _registered = True
    return Handlers()


class Handlers:
    """``jax.ffi.ffi_call`` of each handler, with the result shape given (default: the
    operand's or the right-hand side's)."""

    @staticmethod
    def _call(name, shape, *args, **attrs):
        result = jax.ShapeDtypeStruct(shape, jnp.float64)
        call = jax.ffi.ffi_call(PREFIX + name, result, vmap_method="broadcast_all")
        return np.asarray(call(*args, **attrs))

    def cholesky(self, a, shape=None):
        return self._call("cholesky", shape or np.shape(a), a)

    def tri_solve(self, lower, b, mode, shape=None):
        return self._call("tri_solve", shape or np.shape(b), lower, b, mode=mode)

    def lower_inverse(self, lower, shape=None):
        return self._call("lower_inverse", shape or np.shape(lower), lower)

    def damped_solve(self, a, d, b, shape=None):
        return self._call("damped_solve", shape or np.shape(b), a, d, b)

    def normal_equations(self, rows, c, pairs, n, shapes=None):
        batch = np.shape(rows)[:-2]
        shapes = shapes or (batch + (n, n), batch + (n,))
        results = tuple(jax.ShapeDtypeStruct(s, jnp.float64) for s in shapes)
        call = jax.ffi.ffi_call(
            PREFIX + "normal_equations", results, vmap_method="broadcast_all"
        )
        pairs = np.asarray(pairs, dtype=np.int32).reshape(-1)
        return tuple(np.asarray(r) for r in call(rows, c, pairs=pairs))

    def smallest_right(self, a, start, shape=None, iterations=6, sweeps=8):
        return self._call(
            "smallest_right",
            shape or np.shape(a)[:-1],
            a,
            start,
            iterations=np.int32(iterations),
            sweeps=np.int32(sweeps),
            shift=np.float64(1e-13),
        )


def spd(batch, n, seed=0):
    """SPD matrices (batch + (n, n)) of condition number at most about 5, with noise
    in the strict upper triangle (only the lower one may be read)."""
    rng = np.random.default_rng(seed)
    m = rng.standard_normal(batch + (n, n))
    a = m @ np.swapaxes(m, -1, -2) / n + np.eye(n)
    return a, a + np.triu(rng.standard_normal(a.shape), 1)


@needs_extension
def test_handlers_are_the_extensions_capsules():
    capsules = kernels.handlers()
    assert capsules is not None, kernels.reason
    assert set(capsules) == set(kernels.NAMES)
    assert all(type(c).__name__ == "PyCapsule" for c in capsules.values())
    assert kernels.reason is None
    info = kernels.info()
    assert info["available"] and info["extension_version"] == kernels.VERSION
    assert info["max_n"] == 512
    assert info["damped_max_n"] == DAMPED_MAX_N
    assert info["smallest_max_k"] == 32
    assert not info["stale"], "the extension was built from another dense.cc"


def test_linkopt_kernels_0_turns_them_off(monkeypatch):
    on = kernels.digest()
    monkeypatch.setenv(kernels.ENVIRONMENT, "0")
    assert kernels.handlers() is None
    assert kernels.ENVIRONMENT in kernels.reason
    off = kernels.digest()
    assert len(off) == 64 and off == kernels.digest()
    assert (off != on) == BUILT


@pytest.mark.parametrize(
    "block, why",
    [
        ("sys.modules[name] = None", "installed without its compiled kernels"),
        ("sys.meta_path.insert(0, Broken())", "failed to load: ImportError('boom')"),
    ],
)
def test_a_missing_or_broken_extension_gives_none(block, why):
    """In a fresh process (the extension loads once per process), without JAX."""
    code = (
        "import sys\n"
        f"name = {EXTENSION!r}\n"
        "class Broken:\n"
        "    @staticmethod\n"
        "    def find_spec(fullname, path=None, target=None):\n"
        "        if fullname == name:\n"
        "            raise ImportError('boom')\n"
        f"{block}\n"
        "import linkopt._kernels as k\n"
        "assert k.handlers() is None and k.info()['available'] is False\n"
        "assert 'jax' not in sys.modules\n"
        "print(k.reason)\n"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True
    )
    assert why in out.stdout


@pytest.mark.parametrize("batch", BATCHES, ids=str)
@pytest.mark.parametrize("n", SIZES)
def test_handlers_match_numpy(ffi, n, batch):
    a, noisy = spd(batch, n, seed=n)
    lower = ffi.cholesky(noisy)
    np.testing.assert_allclose(lower, np.linalg.cholesky(a), rtol=1e-12, atol=1e-12)
    assert np.all(np.triu(lower, 1) == 0)
    noisy_lower = lower + np.triu(np.ones_like(lower), 1)  # the upper one is not read
    rng = np.random.default_rng(1)
    for k in (1, 4):  # one right-hand side (its own loop) and several
        b = rng.standard_normal(batch + (n, k))
        expected = [
            np.linalg.solve(lower, b),
            np.linalg.solve(np.swapaxes(lower, -1, -2), b),
            np.linalg.solve(a, b),
        ]
        for mode, x in enumerate(expected):
            got = ffi.tri_solve(noisy_lower, b, mode=np.int32(mode))
            np.testing.assert_allclose(got, x, rtol=1e-12, atol=1e-12)
    inverse = ffi.lower_inverse(noisy_lower)
    np.testing.assert_allclose(inverse, np.linalg.inv(lower), rtol=1e-12, atol=1e-12)
    assert np.all(np.triu(inverse, 1) == 0)


@pytest.mark.parametrize("batch", [*BATCHES, (5,), (7,)], ids=str)
@pytest.mark.parametrize("n", [1, 2, 7, 35, 63, 91, DAMPED_MAX_N])
def test_damped_solve_is_the_cholesky_and_solve_of_the_damped_matrix(ffi, n, batch):
    """Bitwise: the factor and solve of a + d I by the other handlers (four, two or
    one matrices of a batch at a time, in the same operations); and against numpy."""
    a, noisy = spd(batch, n, seed=n)
    rng = np.random.default_rng(n)
    d = rng.uniform(0.0, 2.0, batch)
    b = rng.standard_normal(batch + (n,))
    x = ffi.damped_solve(noisy, d, b)
    damped = noisy + d[..., None, None] * np.eye(n)
    lower = ffi.cholesky(damped)
    expected = ffi.tri_solve(lower, b[..., None], mode=np.int32(2))[..., 0]
    np.testing.assert_array_equal(x, expected)
    exact = np.linalg.solve(a + d[..., None, None] * np.eye(n), b[..., None])
    np.testing.assert_allclose(x, exact[..., 0], rtol=1e-11, atol=1e-12)


@pytest.mark.parametrize("count", [2, 3, 5, 7])
@pytest.mark.parametrize("n", [7, 35, 64, 91, DAMPED_MAX_N, DAMPED_MAX_N + 10])
def test_a_batch_factors_as_its_matrices_one_at_a_time(ffi, n, count):
    """The group paths of the Cholesky handler (batches: four matrices at a time
    where the CPU has AVX2, then two, then one) give the bits of the one-matrix path
    (a single matrix)."""
    _, noisy = spd((count,), n, seed=n)
    batched = ffi.cholesky(noisy)
    for i in range(count):
        np.testing.assert_array_equal(batched[i], ffi.cholesky(noisy[i]))


@pytest.mark.parametrize("failing", [0, 1, 3, 4, 5, 6])
def test_a_failing_matrix_in_a_batch_leaves_the_others_alone(ffi, failing):
    """NaN from the failing pivot on in that matrix only, for the Cholesky and the
    damped solve (its whole x NaN), whichever group and lane it is in (a batch of 7:
    four, two and one)."""
    a, _ = spd((7,), 7, seed=4)
    full = np.linalg.cholesky(a)
    a[failing, 3, 3] = full[failing, 3, :3] @ full[failing, 3, :3] - 1.0
    lower = ffi.cholesky(a)
    nan = np.tril(np.ones((7, 7), bool)) & (np.arange(7) >= 3)[None, :]
    for i in range(7):
        assert np.array_equal(np.isnan(lower[i]), nan if i == failing else 0 * nan)
        np.testing.assert_array_equal(lower[i], ffi.cholesky(a[i]))
    x = ffi.damped_solve(a, np.zeros(7), np.ones((7, 7)))
    assert np.all(np.isnan(x[failing]))
    others = [i for i in range(7) if i != failing]
    np.testing.assert_allclose(
        x[others], np.linalg.solve(a[others], np.ones((6, 7, 1)))[..., 0], rtol=1e-11
    )


def test_handlers_under_vmap_and_jit(ffi):
    """vmap_method="broadcast_all": vmapped calls become one call on the batch."""
    a, noisy = spd((2, 5), 7)
    b = np.random.default_rng(2).standard_normal((2, 5, 7, 3))

    def cho_solve(a, b):
        def call(name, result, *args, **attrs):
            result = jax.ShapeDtypeStruct(result.shape, result.dtype)
            fn = jax.ffi.ffi_call(PREFIX + name, result, vmap_method="broadcast_all")
            return fn(*args, **attrs)

        lower = call("cholesky", a, a)
        return call("tri_solve", b, lower, b, mode=np.int32(2))

    x = jax.jit(jax.vmap(jax.vmap(cho_solve)))(noisy, b)
    np.testing.assert_allclose(x, np.linalg.solve(a, b), rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("pivot", [2, 0, 6])
@pytest.mark.parametrize("bad", [-1.0, np.nan])
def test_a_failing_pivot_gives_nan_from_there_on(ffi, pivot, bad):
    """As dense.cholesky: the columns before the pivot are the factor's, every entry
    of the lower triangle from the pivot's column on is NaN."""
    a, _ = spd((), 7, seed=3)
    full = np.linalg.cholesky(a)
    a[pivot, pivot] = full[pivot, :pivot] @ full[pivot, :pivot] + bad  # pivot**2 = bad
    lower = ffi.cholesky(a)
    nan = np.tril(np.ones((7, 7), bool)) & (np.arange(7) >= pivot)[None, :]
    assert np.array_equal(np.isnan(lower), nan)
    np.testing.assert_allclose(lower[:, :pivot], full[:, :pivot], rtol=1e-12)
    assert np.all(np.triu(lower, 1) == 0)
    assert np.array_equal(np.isnan(jax.jit(dense.cholesky)(a)), nan)


def test_refused_operands_give_errors_not_crashes(ffi):
    n = 513  # one more than the kernels' limit
    big = np.eye(n)
    for call in (
        lambda: ffi.cholesky(big),
        lambda: ffi.lower_inverse(big),
        lambda: ffi.tri_solve(big, np.ones((n, 1)), mode=np.int32(0)),
    ):
        with pytest.raises(Exception, match="exceeds the kernels' limit of 512"):
            call()
    a, _ = spd((), 4)
    b = np.ones((4, 1))
    with pytest.raises(Exception, match="mode must be 0"):
        ffi.tri_solve(a, b, mode=np.int32(3))
    with pytest.raises(Exception, match="expected b of shape"):
        ffi.tri_solve(a, np.ones((5, 1)), mode=np.int32(0))
    with pytest.raises(Exception, match="batch dimensions"):
        ffi.tri_solve(np.stack([a, a]), np.ones((3, 4, 1)), mode=np.int32(0))
    n = DAMPED_MAX_N + 1
    with pytest.raises(Exception, match=f"damped solve's limit of {DAMPED_MAX_N}"):
        ffi.damped_solve(np.eye(n), 1.0, np.ones(n))
    with pytest.raises(Exception, match="expected a"):
        ffi.damped_solve(a, 1.0, np.ones((4, 1)))
    with pytest.raises(Exception, match="expected a"):
        ffi.damped_solve(np.stack([a, a]), 1.0, np.ones((2, 4)))
    with pytest.raises(Exception, match="batch dimensions"):
        ffi.damped_solve(np.stack([a, a]), np.ones(3), np.ones((2, 4)))
    with pytest.raises(Exception, match="result shape differs"):
        ffi.damped_solve(a, 1.0, np.ones(4), shape=(5,))
    with pytest.raises(Exception, match="result shape differs"):
        ffi.cholesky(a, shape=(4, 5))  # would be written past its end
    with pytest.raises(Exception, match="result rank differs"):
        ffi.lower_inverse(a, shape=(16,))
    with pytest.raises(Exception, match=r"\(\.\.\., n, n\)"):
        ffi.cholesky(np.ones((4, 5)), shape=(4, 5))
    # float32: the handlers take float64 only
    with pytest.raises(Exception, match="expected F64"):
        jax.ffi.ffi_call(
            PREFIX + "cholesky", jax.ShapeDtypeStruct((4, 4), jnp.float32)
        )(a.astype(np.float32))


def _gram_and_start(batch: int, m: int, n: int, seed: int):
    """Gram matrices ``JᵀJ`` of random ``(m, n)`` Jacobians, one of them with two
    smallest singular values 1 % apart, and the start blocks of
    ``singularity.smallest_right_vectors``."""
    rng = np.random.default_rng(seed)
    jac = rng.standard_normal((batch, m, n))
    if min(m, n) >= 3:
        u, s, vt = np.linalg.svd(jac[0], full_matrices=False)
        s[-2:] = [1e-3, 1.01e-3]
        jac[0] = (u * s) @ vt
    start = np.random.default_rng(0).standard_normal((n, min(6, n)))
    start = np.broadcast_to(start, (batch,) + start.shape).copy()
    return jac, np.einsum("bmi,bmj->bij", jac, jac), start


@pytest.mark.parametrize(
    "batch, m, n", [(1, 4, 1), (3, 3, 2), (5, 7, 5), (7, 40, 35), (2, 100, 91)]
)
def test_smallest_right_is_the_plain_code(ffi, batch, m, n):
    """The kernel's vector equals the plain-JAX steps' up to sign and round-off (to
    1e-6 here: the first matrix's two smallest eigenvalues of ``JᵀJ`` are 2e-8 apart,
    so round-off of 1e-15 ‖JᵀJ‖ turns its vector by up to about 1e-7); ‖J v‖ is the
    plain code's to 1e-12 (σ is stationary in v) and σ_min of the SVD to 1e-6 (six
    sweeps of inverse iteration leave the random 100 x 91 matrix 5e-8 short)."""
    from linkopt._engine.singularity import plain_smallest

    jac, a, start = _gram_and_start(batch, m, n, seed=n)
    v = ffi.smallest_right(a, start)
    plain = np.asarray(jax.jit(plain_smallest)(a, start))
    sign = np.sign(np.sum(v * plain, axis=1))[:, None]
    np.testing.assert_allclose(v, sign * plain, atol=1e-6)
    np.testing.assert_allclose(v[1:], sign[1:] * plain[1:], atol=1e-11)
    sigma, plain_sigma = (
        np.linalg.norm(np.einsum("bij,bj->bi", jac, x), axis=1) for x in (v, plain)
    )
    np.testing.assert_allclose(sigma, plain_sigma, rtol=1e-12)
    svd = np.linalg.svd(jac, compute_uv=False)[:, -1]
    np.testing.assert_allclose(sigma, svd, rtol=1e-6)


@pytest.mark.parametrize("count", [2, 3, 5, 7])
def test_smallest_right_of_a_batch_is_each_alone(ffi, count):
    """Four, two or one problems side by side give the bits of one at a time."""
    _, a, start = _gram_and_start(count, 40, 35, seed=count)
    batched = ffi.smallest_right(a, start)
    for i in range(count):
        np.testing.assert_array_equal(batched[i], ffi.smallest_right(a[i], start[i]))


def test_smallest_right_of_a_bad_matrix_is_nan_there_only(ffi):
    _, a, start = _gram_and_start(7, 40, 35, seed=1)
    a[2, 5, 5] = -1e6  # not positive definite
    a[4, 0, 0] = np.nan
    v = ffi.smallest_right(a, start)
    assert np.all(np.isnan(v[[2, 4]]))
    assert np.all(np.isfinite(v[[0, 1, 3, 5, 6]]))


def test_smallest_right_refuses_bad_operands(ffi):
    _, a, start = _gram_and_start(2, 40, 35, seed=0)
    with pytest.raises(Exception, match="must be in 1..min"):
        ffi.smallest_right(a[:, :5, :5], start[:, :5, :])  # k = 6 > n = 5
    wide = np.zeros((2, 35, 33))
    with pytest.raises(Exception, match="must be in 1..min"):
        ffi.smallest_right(a, wide)
    with pytest.raises(Exception, match="batch dimensions"):
        ffi.smallest_right(a, start[:1], shape=(2, 35))
    with pytest.raises(Exception, match="expected a"):
        ffi.smallest_right(a, start, shape=(2, 34))
    with pytest.raises(Exception, match="must be >= 0"):
        ffi.smallest_right(a, start, iterations=-1)


@needs_extension
def test_smallest_right_vectors_differentiate_as_the_plain_code():
    """Where the kernel serves it, singularity.smallest_right_vectors takes the plain
    steps' derivative (its callers stop the gradient; a user's may not)."""
    from linkopt._engine import singularity

    jac, _, _ = _gram_and_start(3, 12, 9, seed=2)
    tangent = np.random.default_rng(3).standard_normal(jac.shape)

    def plain(j):
        a = jnp.einsum("bmi,bmj->bij", j, j)
        start = np.random.default_rng(0).standard_normal((9, 6))
        return singularity.plain_smallest(a, jnp.broadcast_to(start, (3, 9, 6)))

    value, derivative = jax.jvp(singularity.smallest_right_vectors, (jac,), (tangent,))
    expected, expected_derivative = jax.jvp(plain, (jac,), (tangent,))
    sign = np.sign(np.sum(value * expected, axis=1))[:, None]
    np.testing.assert_allclose(value, sign * expected, atol=1e-10)
    np.testing.assert_allclose(derivative, expected_derivative, atol=1e-8)


def _two_body_rows(batch, bodies: int, m: int, seed: int = 0):
    """Random row blocks ``batch + (m, 14)``, residuals and static body pairs: rows on
    two bodies in either order, on one body (``-1`` second), on one body twice, and
    rows that name no body at all."""
    rng = np.random.default_rng(seed)
    rows = rng.normal(size=batch + (m, 14))
    c = rng.normal(size=batch + (m,))
    pairs = rng.integers(0, bodies, size=(m, 2))
    pairs[1::5, 1] = -1
    pairs[2::5, 0] = -1
    pairs[3::7, 1] = pairs[3::7, 0]
    pairs[m // 2] = -1
    return rows, c, pairs


def _dense_rows(rows, pairs, bodies: int):
    """The dense ``J`` of :func:`dense.block_normal`'s layout, by numpy."""
    jac = np.zeros(rows.shape[:-1] + (7 * bodies,))
    for r, (i, j) in enumerate(pairs):
        if i >= 0:
            jac[..., r, 7 * i : 7 * i + 7] += rows[..., r, :7]
        if j >= 0:
            jac[..., r, 7 * j : 7 * j + 7] += rows[..., r, 7:]
    return jac


@pytest.mark.parametrize("batch", [*BATCHES, (5,)], ids=str)
@pytest.mark.parametrize("bodies,m", [(1, 3), (5, 38), (10, 72), (40, 200)])
def test_normal_equations_are_the_dense_products(ffi, bodies, m, batch):
    rows, c, pairs = _two_body_rows(batch, bodies, m)
    jtj, jtc = ffi.normal_equations(rows, c, pairs, 7 * bodies)
    jac = _dense_rows(rows, pairs, bodies)
    jt = np.swapaxes(jac, -1, -2)
    np.testing.assert_allclose(jtj, jt @ jac, rtol=1e-13, atol=1e-12)
    np.testing.assert_allclose(jtc, (jt @ c[..., None])[..., 0], rtol=1e-13, atol=1e-12)
    assert np.array_equal(jtj, np.swapaxes(jtj, -1, -2))  # symmetric exactly


def test_block_normal_under_vmap_jit_and_its_derivative():
    """dense.block_normal (the kernel where built) equals the dense product batched,
    and its JVP is the dense product's."""
    rows, c, pairs = _two_body_rows((4,), 6, 30, seed=3)
    size = 42
    fn = jax.jit(jax.vmap(lambda r, v: dense.block_normal(r, v, pairs, size)))
    jtj, jtc = fn(rows, c)
    jac = _dense_rows(rows, pairs, 6)
    np.testing.assert_allclose(jtj, np.swapaxes(jac, 1, 2) @ jac, atol=1e-12)
    np.testing.assert_allclose(jtc, np.einsum("brn,br->bn", jac, c), atol=1e-12)
    rng = np.random.default_rng(4)
    d_rows, d_c = rng.normal(size=rows.shape[1:]), rng.normal(size=c.shape[1:])
    _, (d_jtj, d_jtc) = jax.jvp(
        lambda r, v: dense.block_normal(r, v, pairs, size), (rows[0], c[0]),
        (d_rows, d_c),
    )  # fmt: skip
    d_jac = _dense_rows(d_rows, pairs, 6)
    np.testing.assert_allclose(d_jtj, d_jac.T @ jac[0] + jac[0].T @ d_jac, atol=1e-12)
    np.testing.assert_allclose(d_jtc, d_jac.T @ c[0] + jac[0].T @ d_c, atol=1e-12)

    def loss(normal):  # reverse mode too: the JVP rule transposes
        return lambda r, v: sum(jnp.sum(x**2) for x in normal(r, v))

    def dense_normal(r, v):
        # J[r] = Σ_k rows[r, k] J_k[r], J_k the dense rows of the unit block e_k
        units = np.stack(
            [_dense_rows(np.tile(e, (30, 1)), pairs, 6) for e in np.eye(14)]
        )
        j = jnp.einsum("rk,krn->rn", r, jnp.asarray(units))
        return j.T @ j, j.T @ v

    kernel = jax.grad(loss(lambda r, v: dense.block_normal(r, v, pairs, size)), (0, 1))
    for a, b in zip(
        kernel(rows[0], c[0]), jax.grad(loss(dense_normal), (0, 1))(rows[0], c[0])
    ):
        np.testing.assert_allclose(a, b, rtol=1e-12, atol=1e-10)


def test_normal_equations_refuse_bad_operands(ffi):
    rows, c, pairs = _two_body_rows((), 3, 6)
    with pytest.raises(Exception, match="out of range"):
        ffi.normal_equations(rows, c, np.where(pairs == 0, 3, pairs), 21)
    with pytest.raises(Exception, match="2 m body indices"):
        ffi.normal_equations(rows, c, pairs[:-1], 21)
    with pytest.raises(Exception, match="7 x bodies"):
        ffi.normal_equations(rows, c, pairs, 20)
    with pytest.raises(Exception, match="row count"):
        ffi.normal_equations(rows, c[:-1], pairs, 21)
    with pytest.raises(Exception, match=r"rows \(\.\.\., m, 14\)"):
        ffi.normal_equations(rows[:, :13], c, pairs, 21)
    with pytest.raises(Exception, match="batch dimensions"):
        ffi.normal_equations(
            np.stack([rows, rows]), np.stack([c, c, c]), pairs, 21,
            shapes=((2, 21, 21), (2, 21)),
        )  # fmt: skip
