"""Process-wide JAX configuration: 64-bit floats and the persistent compilation cache.

Imported first by :mod:`linkopt`. The cache lives in a per-user directory,
``$LINKOPT_CACHE_DIR`` if set, else ``$XDG_CACHE_HOME/linkopt/jax`` (default
``~/.cache/linkopt/jax``), so a second process reuses compiled kernels instead of
recompiling them. Float64 is required: a float32 Levenberg–Marquardt solve stalls
at residuals of about 3e-7, far above the 1e-10 loop-closure tolerance we need.
"""

from __future__ import annotations

import os
from pathlib import Path

import jax


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
