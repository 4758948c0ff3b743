"""Process-wide JAX configuration: 64-bit floats and the persistent compilation cache.

Imported first by :mod:`linkopt`. The cache lives in a per-user directory,
``$LINKOPT_CACHE_DIR`` if set, else ``$XDG_CACHE_HOME/linkopt/jax`` (default
``~/.cache/linkopt/jax``), so a second process reuses compiled kernels instead of
recompiling them. Float64 is required: a float32 Levenberg–Marquardt solve stalls
at residuals of about 3e-7, far above the 1e-10 loop-closure tolerance we need.

XLA's CPU runtime runs independent thunks on its intra-op thread pool, and jaxlib's
batched LAPACK kernels (SVD, Cholesky, ...) split their batch into tasks on that same
pool and block until those are done (``jax::ParallelBatchMap``). When every worker is
such a blocked kernel, nobody runs the tasks: on a 2-core machine two LAPACK calls that
happen to be ready at once hang the process for ever (seen with jax 0.10.2, e.g.
``jit(vmap(grad(f_sing ∘ FK)))``; ``--xla_cpu_multi_thread_eigen=false`` does not help).
ParallelBatchMap runs the whole batch inline when the pool has one thread, so unless the
user set ``PJRT_NPROC`` we set it to 1 (read by XLA when it creates its CPU client, i.e.
at the first computation; importing :mod:`linkopt` first guarantees that). The cost
in batched solves per second is measured by ``benchmarks/bench_kinematics.py``.
"""

from __future__ import annotations

import os
from pathlib import Path


def _single_threaded_pool() -> None:
    os.environ.setdefault("PJRT_NPROC", "1")  # takes precedence over NPROC in XLA


_single_threaded_pool()

import jax  # noqa: E402  (PJRT_NPROC must be set first)


def cache_directory() -> Path:
    """Directory of the persistent JAX compilation cache for this user."""
    explicit = os.environ.get("LINKOPT_CACHE_DIR")
    if explicit:
        return Path(explicit)
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "linkopt" / "jax"


def configure() -> None:
    """Enable float64 and the persistent compilation cache (idempotent)."""
    jax.config.update("jax_enable_x64", True)
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
    beside its own, overbook a 2-core machine and every chunk runs several times slower
    (figures in ``benchmarks/bench_optimizer.py``). Every chunk therefore runs with
    OpenBLAS held to one thread (``threadpoolctl``): in the workers for their lifetime,
    in the calling process only while it computes, so the user's own numpy keeps its
    threads. ``threadpoolctl`` only limits libraries already loaded, and jaxlib loads
    scipy's OpenBLAS at its first LAPACK call, so ``scipy.linalg`` (which loads it) is
    imported here, before the limit is set, and not at import of :mod:`linkopt`.
    """
    import scipy.linalg  # noqa: F401  (loads the OpenBLAS that jaxlib calls)
    from threadpoolctl import threadpool_limits

    return threadpool_limits(1, user_api="blas")
