"""Small dense linear algebra in plain JAX operations (no LAPACK custom calls).

jaxlib runs ``jnp.linalg``'s Cholesky, triangular solve, LU, eigh and SVD on CPU as
LAPACK custom calls that split a batch into tasks on XLA's intra-op thread pool and
block until those finish (``jax::ParallelBatchMap``); with as many such calls ready as
the pool has threads, nobody runs the tasks and the process hangs (jaxlib 0.10.2, see
:mod:`linkopt._config`). Everything here is built from ``lax.fori_loop``, dynamic
slices and element-wise arithmetic, so a vmapped batch is one loop over columns whose
body works on the whole batch at once, and nothing ever waits on the pool.

Sizes here are small (≤ ~80: states of 35-70 coordinates, 6 × 6 Ritz matrices, 2 × 2
motor systems). Loops over a matrix dimension are ``fori_loop``s, not Python loops, so
the HLO (and compile time) does not grow with ``n``.

Behaviour outside the happy path (chosen to match what the LAPACK routines give through
``jnp.linalg``, which fill a failed factor with NaN):

* :func:`cholesky` of a matrix that is not positive definite, or holds NaN, gives NaN
  from the first non-positive pivot on (``sqrt`` of a negative number); every solve with
  that factor is then NaN. Only the lower triangle of the input is read.

Compiled kernels. Where linkopt's compiled extension is built (:mod:`linkopt._kernels`,
made by ``pip install`` with the machine's C++ compiler) and the program runs on CPU in
float64, :func:`cholesky`, :func:`solve_lower`, :func:`solve_lower_transpose`,
:func:`cho_solve`, :func:`damped_solve` and :func:`lower_inverse` call its XLA FFI
handlers instead (and :func:`smallest_right` is σ_min's iteration as one handler,
:mod:`linkopt._engine.singularity`; :func:`block_normal` the constraint solves' ``JᵀJ``
and ``Jᵀr`` from their two-body row blocks): the same algorithms as plain loops over one
matrix at a time (the Cholesky factor and :func:`damped_solve` over two or four of a
batch side by side, in the same operations), several times faster than XLA:CPU's loops
over the batch, and a custom call is a single instruction where the loops were
hundreds, so the programs that use them also compile faster (run
``benchmarks/bench_kinematics.py`` or ``benchmarks/bench_compile.py`` with and without
``LINKOPT_KERNELS=0`` to compare). The handlers run on the calling thread (no thread
pool, so nothing can deadlock) and agree with the plain-JAX code to round-off
(``tests/test_kernels.py``, ``tests/test_kernel_paths.py``); one difference: an
exactly zero first pivot gives NaN there, 0 here. Their derivatives, where a caller
differentiates through them, are the plain-JAX code's (``jax.custom_jvp``). Without
the extension, with ``LINKOPT_KERNELS=0``, on another platform, in another precision or
for an order above the kernels' limit, the plain-JAX code below runs.

Derivatives: :func:`solve_spd` is a ``lax.custom_linear_solve``, so its JVP and
transpose are further solves with the same factor (the matrix's derivative enters only
through ``A x``); the factorisation itself is never differentiated.

General square matrices (LU, :func:`linkopt._engine.dense_lu.solve`, ``det``) are in
:mod:`linkopt._engine.dense_lu`, the small symmetric eigenproblem in
:mod:`linkopt._engine.eigh`.
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from .. import (
    _config,  # noqa: F401  (float64 on before any array)
    _kernels,
)


def _as_matrix(b):
    """``(n, k)`` view of a right-hand side and whether it was a vector."""
    return (b[:, None], True) if b.ndim == 1 else (b, False)


#: Panel width of the triangular solves: ``n`` is padded to a multiple of it, and each
#: ``fori_loop`` step handles one panel of rows (a product with the finished part, then
#: ``PANEL`` rows unrolled), so a solve is ``n / PANEL`` loop steps, not ``n``.
PANEL = 8


def _padded(a: Float[Array, "n n"]) -> Float[Array, "N N"]:
    """``a`` in the top-left corner of an identity of the next multiple of
    :data:`PANEL` (positive definite and triangular structure are kept)."""
    n = a.shape[-1]
    size = -(-n // PANEL) * PANEL
    if size == n:
        return a
    return jnp.eye(size, dtype=a.dtype).at[:n, :n].set(a)


def _pad_rows(b: Float[Array, "n k"], size: int) -> Float[Array, "N k"]:
    return b if b.shape[0] == size else jnp.pad(b, ((0, size - b.shape[0]), (0, 0)))


def _plain_cholesky(a: Float[Array, "n n"]) -> Float[Array, "n n"]:
    """Lower Cholesky factor ``L`` of ``a = L Lᵀ`` (left-looking, one column per
    ``fori_loop`` step; reads the lower triangle only; NaN from the first non-positive
    pivot on).

    One column a step (a matrix-vector product with the finished columns) rather than
    panels of :data:`PANEL` columns: panels ran slower, both alone and vmapped over
    chunks of 32, because the panel's unrolled column updates each pass over the whole
    batch (``benchmarks/bench_kinematics.py`` times the solves)."""
    n = a.shape[-1]
    rows = jnp.arange(n)

    def column(j, lower):
        row_j = jax.lax.dynamic_index_in_dim(lower, j, 0, keepdims=False)  # L[j, :j]
        col = jax.lax.dynamic_index_in_dim(a, j, 1, keepdims=False) - lower @ row_j
        pivot = jnp.sqrt(jax.lax.dynamic_index_in_dim(col, j, 0, keepdims=False))
        new = jnp.where(rows > j, col / pivot, jnp.where(rows == j, pivot, 0.0))
        return jax.lax.dynamic_update_index_in_dim(lower, new, j, 1)

    return jax.lax.fori_loop(0, n, column, jnp.zeros_like(a))


def _plain_solve_lower(
    lower: Float[Array, "n n"], b: Float[Array, "n ..."]
) -> Float[Array, "n ..."]:
    """``x`` with ``L x = b`` for lower-triangular ``L`` (forward substitution by
    panels of :data:`PANEL` rows; ``b`` a vector or an ``(n, k)`` matrix; only the
    lower triangle of ``L`` is read)."""
    rhs, vector = _as_matrix(b)
    n = lower.shape[-1]
    padded = _padded(jnp.tril(lower))
    size = padded.shape[-1]
    rhs_p = _pad_rows(rhs, size)

    def panel(k, x):
        j = k * PANEL
        strip = jax.lax.dynamic_slice_in_dim(padded, j, PANEL, 0)  # L[j:j+P, :]
        r = jax.lax.dynamic_slice_in_dim(rhs_p, j, PANEL, 0) - strip @ x
        diag = jax.lax.dynamic_slice_in_dim(strip, j, PANEL, 1)  # rows >= j of x: 0
        ys = []
        for c in range(PANEL):
            y = r[c] - sum((diag[c, d] * ys[d] for d in range(c)), jnp.zeros_like(r[c]))
            ys.append(y / diag[c, c])
        return jax.lax.dynamic_update_slice_in_dim(x, jnp.stack(ys), j, 0)

    x = jax.lax.fori_loop(0, size // PANEL, panel, jnp.zeros_like(rhs_p))[:n]
    return x[:, 0] if vector else x


def solve_upper(
    upper: Float[Array, "n n"], b: Float[Array, "n ..."]
) -> Float[Array, "n ..."]:
    """``x`` with ``U x = b`` for upper-triangular ``U`` (back substitution)."""
    rhs, vector = _as_matrix(b)
    n = upper.shape[-1]

    def row(k, x):
        i = n - 1 - k
        u_i = jax.lax.dynamic_index_in_dim(upper, i, 0, keepdims=False)
        b_i = jax.lax.dynamic_index_in_dim(rhs, i, 0, keepdims=False)
        value = (b_i - u_i @ x) / jax.lax.dynamic_index_in_dim(
            u_i, i, 0, keepdims=False
        )  # rows <= i of x are still zero
        return jax.lax.dynamic_update_index_in_dim(x, value, i, 0)

    x = jax.lax.fori_loop(0, n, row, jnp.zeros_like(rhs))
    return x[:, 0] if vector else x


def _plain_solve_lower_transpose(
    lower: Float[Array, "n n"], b: Float[Array, "n ..."]
) -> Float[Array, "n ..."]:
    """``x`` with ``Lᵀ x = b`` (back substitution by panels of :data:`PANEL` rows,
    reading the columns of ``L``; only its lower triangle is read)."""
    rhs, vector = _as_matrix(b)
    n = lower.shape[-1]
    padded = _padded(jnp.tril(lower))
    size = padded.shape[-1]
    rhs_p = _pad_rows(rhs, size)
    panels = size // PANEL

    def panel(k, x):
        j = (panels - 1 - k) * PANEL
        strip = jax.lax.dynamic_slice_in_dim(padded, j, PANEL, 1)  # L[:, j:j+P]
        r = jax.lax.dynamic_slice_in_dim(rhs_p, j, PANEL, 0) - strip.T @ x
        diag = jax.lax.dynamic_slice_in_dim(strip, j, PANEL, 0)  # rows <= j of x: 0
        ys = [None] * PANEL
        for c in reversed(range(PANEL)):
            later = (diag[d, c] * ys[d] for d in range(c + 1, PANEL))
            ys[c] = (r[c] - sum(later, jnp.zeros_like(r[c]))) / diag[c, c]
        return jax.lax.dynamic_update_slice_in_dim(x, jnp.stack(ys), j, 0)

    x = jax.lax.fori_loop(0, panels, panel, jnp.zeros_like(rhs_p))[:n]
    return x[:, 0] if vector else x


def _plain_cho_solve(lower: Float[Array, "n n"], b: Float[Array, "n ..."]):
    return _plain_solve_lower_transpose(lower, _plain_solve_lower(lower, b))


def _plain_lower_inverse(lower: Float[Array, "n n"]) -> Float[Array, "n n"]:
    """``L⁻¹`` of a lower-triangular matrix (forward substitution on the identity)."""
    return _plain_solve_lower(lower, jnp.eye(lower.shape[-1], dtype=lower.dtype))


# ---------------------------------------------------------------------------------
# The compiled kernels (module docstring) and the public entry points.


def _register_now() -> None:
    """Make ``jax.ffi.register_ffi_target`` on the CPU register at once, so that XLA's
    refusal is raised there (where :func:`_register` catches it) rather than when the
    CPU backend starts, which it would then fail, and every JAX computation with it.

    jaxlib queues CPU registrations until its CPU client is made, which installs
    ``_xla.register_custom_call_target`` as the CPU handler; installing that same
    function first (a no-op once the client exists) registers at once. Where this
    jaxlib lacks it, registration stays queued and the check of the FFI API versions
    (:mod:`linkopt._kernels`) is the guard."""
    from jax._src.lib import xla_client

    native = getattr(
        getattr(xla_client, "_xla", None), "register_custom_call_target", None
    )
    if native is not None and hasattr(xla_client, "register_custom_call_handler"):
        xla_client.register_custom_call_handler("cpu", native)


def _register() -> dict[str, str] | None:
    """Register the compiled handlers with XLA once per process (before any program
    that calls them is deserialised or loaded); their target names, or None (the
    plain-JAX code runs; :func:`linkopt._kernels.refuse` warns where XLA refused
    them)."""
    handlers = _kernels.handlers()
    if handlers is None or not hasattr(jax, "ffi"):  # jax.ffi: jax 0.4.38 and later
        return None
    targets = {}
    try:
        _register_now()
        for key, capsule in handlers.items():
            name = f"linkopt_{key}_v{_kernels.VERSION}"
            jax.ffi.register_ffi_target(name, capsule, platform="cpu")
            targets[key] = name
    except Exception as exc:  # XLA refused a handler: none of them is used
        _kernels.refuse(f"XLA refused to register them ({exc})")
        return None
    return targets


@functools.cache
def _kernel_state() -> dict:
    """The kernels registered with XLA on first use (nothing at import), and their
    limits: the values of :data:`LAZY`."""
    targets = _register()
    on = targets is not None
    return {
        "TARGETS": targets,
        "KERNEL_MAX_N": _kernels.max_n() if on else 0,
        "DAMPED_MAX_N": _kernels.damped_max_n() if on else 0,
        "SMALLEST_MAX_K": _kernels.smallest_max_k() if on else 0,
        "EXPORT_CHECKS": tuple(
            jax.export.DisabledSafetyCheck.custom_call(target)
            for target in (targets or {}).values()
        ),
    }


#: Module attributes computed on first use (PEP 562): ``TARGETS``, the FFI target
#: names of the compiled kernels or None where they are not available;
#: ``KERNEL_MAX_N``, the largest matrix order the kernels take; ``DAMPED_MAX_N``, the
#: largest order :func:`damped_solve`'s fused kernel takes; ``SMALLEST_MAX_K``, the
#: widest start block of :func:`smallest_right`'s kernel; ``EXPORT_CHECKS``, the
#: ``jax.export`` safety checks to turn off for programs that call the kernels.
LAZY = ("TARGETS", "KERNEL_MAX_N", "DAMPED_MAX_N", "SMALLEST_MAX_K", "EXPORT_CHECKS")


def __getattr__(name: str):
    if name in LAZY:
        return _kernel_state()[name]
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def kernels_serve(*arrays) -> bool:
    """Whether the compiled kernels serve these arrays, whatever their shapes: the
    extension is registered, the program runs on the CPU and every array is float64
    (module docstring)."""
    return (
        _kernel_state()["TARGETS"] is not None
        and all(a.dtype == jnp.float64 for a in arrays)
        and jax.default_backend() == "cpu"
    )


def _use_kernel(*arrays) -> bool:
    """Whether the kernels serve these arrays (module docstring)."""
    return (
        kernels_serve(*arrays)
        and arrays[0].shape[-1] <= _kernel_state()["KERNEL_MAX_N"]
    )


def call_kernel(
    key: str, result, *args, aliases=None, vmap_method="broadcast_all", **attributes
):
    """The compiled handler ``key`` (:data:`linkopt._kernels.NAMES`) on ``args``, its
    result shaped as ``result`` (an array or a tuple of them, or of
    ``jax.ShapeDtypeStruct``); where :func:`kernels_serve` says so."""
    return jax.ffi.ffi_call(
        _kernel_state()["TARGETS"][key],
        jax.tree.map(lambda r: jax.ShapeDtypeStruct(r.shape, r.dtype), result),
        vmap_method=vmap_method,
        input_output_aliases=aliases,
    )(*args, **attributes)


def with_plain_derivative(kernel, plain):
    """``kernel`` whose derivative is ``plain``'s (the same function in plain JAX)."""
    fn = jax.custom_jvp(kernel)
    fn.defjvp(lambda primals, tangents: jax.jvp(plain, primals, tangents))
    return fn


def _kernel_cholesky(a):
    return call_kernel("cholesky", a, a)


def _tri_solve(mode: int, plain):
    """A triangular solve of the kernel (``mode`` 0: ``L x = b``, 1: ``Lᵀ x = b``, 2:
    ``L Lᵀ x = b``) for ``b`` a vector or an ``(n, k)`` matrix."""

    def kernel(lower, b):
        rhs, vector = _as_matrix(b)
        x = call_kernel(
            "tri_solve", rhs, lower, rhs, aliases={1: 0}, mode=np.int32(mode)
        )
        return x[:, 0] if vector else x

    return with_plain_derivative(kernel, plain)


def _plain_damped_solve(a, damping, b):
    return _plain_cho_solve(_plain_cholesky(_damped(a, damping)), b)


def _damped(a, damping):
    return a + damping * jnp.eye(a.shape[-1], dtype=a.dtype)


_KERNELS = {
    "cholesky": with_plain_derivative(_kernel_cholesky, _plain_cholesky),
    "damped_solve": with_plain_derivative(
        lambda a, damping, b: call_kernel("damped_solve", b, a, damping, b),
        _plain_damped_solve,
    ),
    "solve_lower": _tri_solve(0, _plain_solve_lower),
    "solve_lower_transpose": _tri_solve(1, _plain_solve_lower_transpose),
    "cho_solve": _tri_solve(2, _plain_cho_solve),
    "lower_inverse": with_plain_derivative(
        lambda lower: call_kernel("lower_inverse", lower, lower), _plain_lower_inverse
    ),
}


def cholesky(a: Float[Array, "n n"]) -> Float[Array, "n n"]:
    """Lower Cholesky factor ``L`` of ``a = L Lᵀ`` (reads the lower triangle only; NaN
    from the first non-positive pivot on; module docstring)."""
    if _use_kernel(a):
        return _KERNELS["cholesky"](a)
    return _plain_cholesky(a)


def solve_lower(
    lower: Float[Array, "n n"], b: Float[Array, "n ..."]
) -> Float[Array, "n ..."]:
    """``x`` with ``L x = b`` for lower-triangular ``L`` (``b`` a vector or an
    ``(n, k)`` matrix; only the lower triangle of ``L`` is read)."""
    if _use_kernel(lower, b):
        return _KERNELS["solve_lower"](lower, b)
    return _plain_solve_lower(lower, b)


def solve_lower_transpose(
    lower: Float[Array, "n n"], b: Float[Array, "n ..."]
) -> Float[Array, "n ..."]:
    """``x`` with ``Lᵀ x = b`` (only the lower triangle of ``L`` is read)."""
    if _use_kernel(lower, b):
        return _KERNELS["solve_lower_transpose"](lower, b)
    return _plain_solve_lower_transpose(lower, b)


def cho_solve(lower: Float[Array, "n n"], b: Float[Array, "n ..."]):
    """``x`` with ``L Lᵀ x = b`` from the factor of :func:`cholesky` (not
    differentiable in ``lower``; use :func:`solve_spd` for that)."""
    if _use_kernel(lower, b):
        return _KERNELS["cho_solve"](lower, b)
    return _plain_cho_solve(lower, b)


def damped_solve(
    a: Float[Array, "n n"], damping: Float[Array, ""], b: Float[Array, " n"]
) -> Float[Array, " n"]:
    """``x`` with ``(a + damping I) x = b``: :func:`cho_solve` of the
    :func:`cholesky` of ``a + damping I`` (its lower triangle read; NaN where it is
    not positive definite), in one kernel call where the kernels serve it (the same
    numbers: a Levenberg–Marquardt step is this one call, not an addition and two
    kernels). Its derivative is the plain-JAX code's, through the factorisation loop
    (:func:`solve_spd` differentiates more cheaply)."""
    damping = jnp.asarray(damping, dtype=a.dtype)
    if (
        b.ndim == 1
        and a.shape[-1] <= _kernel_state()["DAMPED_MAX_N"]
        and _use_kernel(a, damping, b)
    ):
        return _KERNELS["damped_solve"](a, damping, b)
    return cho_solve(cholesky(_damped(a, damping)), b)


def serves_smallest_right(a: Float[Array, "B n n"], k: int) -> bool:
    """Whether :func:`smallest_right` runs for these Gram matrices and a start block
    of ``k`` columns (the kernels are in use and take the sizes)."""
    return k <= min(_kernel_state()["SMALLEST_MAX_K"], a.shape[-1]) and _use_kernel(a)


def smallest_right(
    a: Float[Array, "B n n"],
    start: Float[Array, "B n k"],
    *,
    iterations: int,
    sweeps: int,
    shift: float,
) -> Float[Array, "B n"]:
    """The kernel of :func:`linkopt._engine.singularity.smallest_right_vectors` after
    its Gram matrices ``a`` (where :func:`serves_smallest_right`): the same steps in
    one call (``dense.cc``, ``LkSmallestRight``). Not differentiable: its caller
    defines the derivative."""
    return call_kernel(
        "smallest_right",
        jax.ShapeDtypeStruct(a.shape[:-1], a.dtype),
        a,
        start,
        iterations=np.int32(iterations),
        sweeps=np.int32(sweeps),
        shift=np.float64(shift),
    )


def serves_block_normal(rows: Float[Array, "m 14"], size: int) -> bool:
    """Whether :func:`block_normal` runs in the compiled kernel for these rows and a
    state of ``size`` coordinates."""
    return size <= _kernel_state()["KERNEL_MAX_N"] and _use_kernel(rows)


def block_normal(
    rows: Float[Array, "m 14"],
    residual: Float[Array, " m"],
    pairs: np.ndarray,
    size: int,
) -> tuple[Float[Array, "n n"], Float[Array, " n"]]:
    """``(JᵀJ, Jᵀc)`` of the ``(m, size)`` matrix ``J`` whose row ``r`` holds
    ``rows[r, :7]`` in the 7 columns of body ``pairs[r, 0]`` and ``rows[r, 7:]`` in
    those of body ``pairs[r, 1]`` (static, ``-1`` for none), in one call of the
    compiled kernel (``LkNormalEquations``; where :func:`serves_block_normal`): the
    constraint solves' normal equations without the mostly-zero dense ``J``. Its
    derivative is that of the dense product."""
    pairs = np.ascontiguousarray(pairs, dtype=np.int32).reshape(-1)
    return _block_normal(rows, residual, pairs.tobytes(), size)


@functools.partial(jax.custom_jvp, nondiff_argnums=(2, 3))
def _block_normal(rows, residual, pairs: bytes, size: int):
    batch = rows.shape[:-2]
    return jax.ffi.ffi_call(
        _kernel_state()["TARGETS"]["normal_equations"],
        (
            jax.ShapeDtypeStruct(batch + (size, size), rows.dtype),
            jax.ShapeDtypeStruct(batch + (size,), rows.dtype),
        ),
        vmap_method="broadcast_all",
    )(rows, residual, pairs=np.frombuffer(pairs, dtype=np.int32))


@_block_normal.defjvp
def _block_normal_jvp(pairs, size, primals, tangents):
    def plain(rows, residual):
        jac = rows_matrix(rows, np.frombuffer(pairs, np.int32).reshape(-1, 2), size)
        return jac.T @ jac, jac.T @ residual

    return _block_normal(*primals, pairs, size), jax.jvp(plain, primals, tangents)[1]


def rows_matrix(rows: Float[Array, "m 14"], pairs: np.ndarray, size: int):
    """The dense ``J`` ``(m, size)`` of :func:`block_normal`'s rows and pairs."""
    onehot = np.zeros((rows.shape[0], 2, size // 7))
    for side in range(2):
        used = np.flatnonzero(pairs[:, side] >= 0)
        onehot[used, side, pairs[used, side]] = 1.0
    blocks = rows.reshape(-1, 2, 1, 7) * jnp.asarray(onehot)[..., None]
    return (blocks[:, 0] + blocks[:, 1]).reshape(-1, size)


def lower_inverse(lower: Float[Array, "n n"]) -> Float[Array, "n n"]:
    """``L⁻¹`` of a lower-triangular matrix."""
    if _use_kernel(lower):
        return _KERNELS["lower_inverse"](lower)
    return _plain_lower_inverse(lower)


def solve_spd(a: Float[Array, "n n"], b: Float[Array, "n ..."]):
    """``a⁻¹ b`` for symmetric positive definite ``a`` by Cholesky; differentiable in
    both arguments (module docstring), NaN where ``a`` is not positive definite."""
    lower = cholesky(jax.lax.stop_gradient(a))
    return jax.lax.custom_linear_solve(
        lambda x: a @ x,
        b,
        solve=lambda _, rhs: cho_solve(lower, rhs),
        symmetric=True,
    )
