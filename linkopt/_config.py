"""JAX set up for linkopt: float64, the compilation caches where asked, and ``jit``.

**Float64, the one change to a process made on import.** Importing this module (which
every linkopt module that computes with JAX does) turns on ``jax_enable_x64``:
linkopt's Levenberg–Marquardt solves need float64 (in float32 they stall at residuals
far above the 1e-10 loop-closure tolerance), and the flag must be on before any array
is made. ``import linkopt`` alone does not import this module; the first public name
used (other than an error type) does. Nothing else is changed: no environment
variable, no other JAX option, no JAX function (``tests/test_import_effects.py``).

**The caches, where asked.** :func:`use_cache` points JAX's persistent compilation
cache at linkopt's folder through JAX's public options, bounded, and turns on the
traced programs' cache (:mod:`linkopt._cache`); the command line asks for it, a
library user may. XLA's thread pool is left as the user set it (no LAPACK call runs
inside linkopt's programs: :mod:`linkopt._engine.dense`).
"""

from __future__ import annotations

import functools
import os
import warnings
from pathlib import Path

import jax

from . import _cache
from ._errors import InputError

#: The one JAX option linkopt sets without being asked (module docstring).
jax.config.update("jax_enable_x64", True)


def use_cache(directory: str | os.PathLike | None = None) -> Path | None:
    """Keep compiled programs on disk, in ``directory`` (default
    ``$LINKOPT_CACHE_DIR``, else ``~/.cache/linkopt/jax``), so a later process reuses
    them instead of compiling: JAX's persistent compilation cache, bounded to its share
    of ``$LINKOPT_CACHE_SIZE_MB``, and linkopt's traced programs. Call it before the
    first computation; the folder, or None where it cannot be made (then nothing is
    cached on disk)."""
    _cache.request(directory)
    return _apply(_cache.requested())


def adopt(use: _cache.Use | None) -> None:
    """Use the caches another process uses (``use``, from
    :func:`linkopt._cache.requested`): what a spawned worker or a Dask worker runs
    first; nothing for None."""
    if use is not None:
        use_cache(use.directory)


def _apply(use: _cache.Use | None) -> Path | None:
    """Set JAX's cache options for ``use``; the folder, or None."""
    if use is None:
        return None
    root = use.root()
    executables = root / _cache.FOLDERS["executables"]
    try:
        executables.mkdir(parents=True, exist_ok=True)
        _cache.mark_executables(executables)
    except OSError:
        _cache.request_none()
        return None  # read-only home: run without the caches rather than fail
    bound = _executables_bound()
    jax.config.update("jax_compilation_cache_dir", str(executables))
    jax.config.update("jax_compilation_cache_max_size", bound)
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.05)
    jax.config.update("jax_persistent_cache_min_entry_size_bytes", 0)
    return root


def _executables_bound() -> int:
    """``jax_compilation_cache_max_size``: the executables' share of the limit, or -1
    (unbounded) without ``filelock`` or with an invalid ``$LINKOPT_CACHE_SIZE_MB``
    (a warning names it; ``linkopt cache info`` refuses it)."""
    if not _cache.info_bounded():
        return -1
    try:
        return _cache.limit("executables")
    except InputError as err:
        warnings.warn(f"linkopt cache not bounded: {err}", RuntimeWarning, stacklevel=3)
        return -1


_apply(_cache.requested())  # asked for before JAX was set up (the command line)


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
