"""Process-wide JAX configuration: 64-bit floats and the persistent compilation cache.

Imported first by :mod:`linkopt`. The cache lives in a per-user directory,
``$LINKOPT_CACHE_DIR`` if set, else ``$XDG_CACHE_HOME/linkopt/jax`` (default
``~/.cache/linkopt/jax``), so a second process reuses compiled kernels instead of
recompiling them; :mod:`linkopt._cache` bounds it and writes it atomically.
Float64 is required: a float32 Levenberg–Marquardt solve stalls at residuals of about
3e-7, far above the 1e-10 loop-closure tolerance we need.

XLA's thread pool is left as the user (or XLA) set it. jaxlib's batched LAPACK kernels
(Cholesky, triangular solve, LU, eigh, SVD) split their batch into tasks on XLA's
intra-op pool and block until those are done (``jax::ParallelBatchMap``); when every
pool thread is such a blocked kernel nobody runs the tasks, and on a 2-core machine the
process hung (jax 0.10.2, e.g. ``jit(vmap(grad(f_sing ∘ FK)))``). linkopt used to set
``PJRT_NPROC=1`` on import to avoid it, at the cost of one core per process. No longer
needed: the linear algebra inside linkopt's jitted programs is written in plain JAX
(:mod:`linkopt._engine.dense`), so those programs contain no LAPACK call.
``tests/test_no_lapack.py`` guards it: it lowers the hot-path programs and fails on any
LAPACK custom call, and runs ``jit(vmap(grad(f_sing ∘ FK)))`` in a subprocess without
``PJRT_NPROC`` under a timeout. numpy/scipy LAPACK outside jit is unaffected.
"""

from __future__ import annotations

import functools

import jax

from ._cache import cache_directory, install


def configure() -> None:
    """Enable float64 and the persistent compilation cache, bounded
    (:mod:`linkopt._cache`); idempotent."""
    jax.config.update("jax_enable_x64", True)
    install()
    directory = cache_directory()
    try:
        directory.mkdir(parents=True, exist_ok=True)
    except OSError:
        return  # read-only home: run without the cache rather than fail
    jax.config.update("jax_compilation_cache_dir", str(directory))
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.05)
    jax.config.update("jax_persistent_cache_min_entry_size_bytes", 0)


configure()


def one_blas_thread():
    """OpenBLAS held to one thread while linkopt computes; also a context manager that
    restores the previous limits.

    jaxlib's LAPACK kernels call the OpenBLAS that scipy ships, which starts one thread
    per core and keeps it spinning between calls: two processes, each with that thread
    beside its own, overbook a 2-core machine and every chunk runs several times
    slower. Every chunk therefore runs with
    OpenBLAS held to one thread (``threadpoolctl``): in the workers for their lifetime,
    in the calling process only while it computes, so the user's own numpy keeps its
    threads. ``threadpoolctl`` only limits libraries already loaded, and jaxlib loads
    scipy's OpenBLAS at its first LAPACK call, so ``scipy.linalg`` (which loads it) is
    imported here, before the limit is set, and not at import of :mod:`linkopt`.
    """
    import scipy.linalg  # noqa: F401  (loads the OpenBLAS that jaxlib calls)
    from threadpoolctl import threadpool_limits

    return threadpool_limits(1, user_api="blas")


#: XLA options of every program linkopt compiles (:func:`jit`), chosen for the first
#: run's wait without slowing the warm one (``benchmarks/bench_compile.py``,
#: ``benchmarks/bench_cold_start.py`` and ``benchmarks/bench_kinematics.py`` measure
#: all three):
#:
#: * LLVM's expensive passes off: less compilation, run time unchanged.
#: * XLA:CPU's older loop emitters instead of its MLIR fusion emitters: linkopt's
#:   programs are a thousand small element-wise fusions (the analytic Jacobian blocks
#:   of :mod:`linkopt._engine.jacobian`), which the older emitters compile faster and
#:   run no slower.
#: * LLVM optimisation level 1 instead of 2: less compilation, the same run time.
#:
#: Results agree with the default options to round-off of the iterative solves
#: (``tests/test_reference_values.py``). Passed per program, so a user's own JAX
#: programs in the same process are untouched (an ``XLA_FLAGS`` setting would change
#: them too).
COMPILER_OPTIONS = {
    "xla_llvm_disable_expensive_passes": True,
    "xla_cpu_use_fusion_emitters": False,
    "xla_backend_optimization_level": 1,
}


def traced(*args) -> bool:
    """Whether any leaf of ``args`` is a JAX tracer (a call inside a trace)."""
    return any(
        isinstance(leaf, jax.core.Tracer) for leaf in jax.tree_util.tree_leaves(args)
    )


class _Program:
    """A jitted function compiled with :data:`COMPILER_OPTIONS` when called at top
    level, and plain inside another trace (JAX takes compiler options only on a
    top-level jit; a nested one becomes part of the caller's program, compiled with
    the caller's options). ``lower`` lowers the top-level version."""

    def __init__(self, fn, kwargs):
        # name and docstring only: a function made by jax.value_and_grad of another
        # _Program carries that one's attributes in its __dict__, which must not
        # replace these
        functools.update_wrapper(self, fn, updated=())
        self._plain = jax.jit(fn, **kwargs)
        self._tuned = jax.jit(fn, compiler_options=COMPILER_OPTIONS, **kwargs)

    def __call__(self, *args, **kwargs):
        nested = traced(args, kwargs)
        return (self._plain if nested else self._tuned)(*args, **kwargs)

    def lower(self, *args, **kwargs):
        return self._tuned.lower(*args, **kwargs)


def jit(fn=None, **kwargs):
    """``jax.jit`` with :data:`COMPILER_OPTIONS` at top level (:class:`_Program`);
    usable as ``jit(fn, ...)``, ``partial(jit, ...)`` and ``@jit``."""
    if fn is None:
        return lambda f: _Program(f, kwargs)
    return _Program(fn, kwargs)


def stored_record(name: str):
    """Class decorator: register a frozen dataclass whose fields are all arrays as a
    pytree that a stored program (``jax.export``) may return, serialized as ``name``."""

    def register(cls):
        jax.tree_util.register_dataclass(cls)
        jax.export.register_pytree_node_serialization(
            cls,
            serialized_name=name,
            serialize_auxdata=lambda _: b"",  # no meta fields
            deserialize_auxdata=lambda _: (),
        )
        return cls

    return register
