"""Process-wide JAX configuration: 64-bit floats and the persistent compilation cache.

Imported first by :mod:`linkopt`. The cache lives in a per-user directory,
``$LINKOPT_CACHE_DIR`` if set, else ``$XDG_CACHE_HOME/linkopt/jax`` (default
``~/.cache/linkopt/jax``), so a second process reuses compiled kernels instead of
recompiling them. Float64 is required: a float32 Levenberg–Marquardt solve stalls
at residuals of about 3e-7, far above the 1e-10 loop-closure tolerance we need.

XLA's CPU runtime runs independent thunks on its intra-op (Eigen) thread pool, and
jaxlib's batched LAPACK kernels (SVD, Cholesky) fan their batch out into that same
pool and block until it is done. On a 2-core machine two such kernels running at
once take both workers and wait for each other forever (seen with jax 0.10.2:
``jit(vmap(grad(f_sing ∘ FK)))`` hung in ``jax::ParallelBatchMap``). We therefore
append ``--xla_cpu_multi_thread_eigen=false`` to ``XLA_FLAGS`` unless the user set
that flag. It must be in place before JAX creates its CPU client, i.e. before the
first computation; importing :mod:`linkopt` first guarantees that.
"""

from __future__ import annotations

import os
from pathlib import Path

_EIGEN_FLAG = "--xla_cpu_multi_thread_eigen"


def _single_threaded_eigen() -> None:
    flags = os.environ.get("XLA_FLAGS", "")
    if _EIGEN_FLAG not in flags:
        os.environ["XLA_FLAGS"] = f"{flags} {_EIGEN_FLAG}=false".strip()


_single_threaded_eigen()

import jax  # noqa: E402  (XLA_FLAGS must be set first)


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
