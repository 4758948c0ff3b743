"""Compiled kernels: XLA FFI handlers for batched dense linear algebra on the CPU.

``linkopt._kernels._dense`` is built from ``dense.cc`` when linkopt is installed
(``setup.py``), when a C++17 compiler is there; without one linkopt installs without it
and computes with its plain-JAX code. :func:`handlers` gives the handlers as capsules
for ``jax.ffi.register_ffi_target(name, capsule, platform="cpu")``, or None when they
cannot be used (:data:`reason` says why); ``LINKOPT_KERNELS=0`` turns them off.
:func:`digest` keys compiled programs by the handlers they may call.

The extension records the XLA FFI API version of the headers it was built against, and
the jaxlib that shipped them. The running jaxlib's version is read from its own headers
(``jaxlib/include/xla/ffi/api/c_api.h``, what ``jax.ffi.include_dir()`` gives, found
without importing jaxlib); XLA registers a handler only if its major version is the
running one and its minor version no newer, so an extension built against a newer FFI
(a wheel built with a newer jaxlib than the one it is installed with) is not used:
:func:`handlers` returns None and warns once (:class:`KernelsWarning`) with how to
rebuild. :mod:`linkopt._engine.dense` registers the handlers inside a guard too; a
registration XLA refuses all the same is reported by :func:`refuse`, with the same
outcome. Either way linkopt computes with its plain-JAX code.

The handlers (float64, row-major, every leading dimension a batch dimension; the
dense ones' matrix order ``n`` at most ``_dense.max_n()``, 512, else an error; the
band's any number ``B`` of block rows):

* ``cholesky``: ``a (..., n, n)`` -> the lower Cholesky factor (reads the lower
  triangle; NaN from the first non-positive pivot on);
* ``tri_solve``: ``L (..., n, n)``, ``b (..., n, k)``, attribute ``mode`` (int32):
  0 solves ``L x = b``, 1 ``Lᵀ x = b``, 2 ``L Lᵀ x = b``;
* ``lower_inverse``: ``L (..., n, n)`` -> ``L⁻¹``;
* ``damped_solve``: ``a (..., n, n)``, ``d (...)``, ``b (..., n)`` -> ``(a + d I)⁻¹ b``
  (``cholesky`` of ``a + d I`` and ``tri_solve`` mode 2 in one call, the same numbers;
  order at most ``_dense.damped_max_n()``, 160);
* ``smallest_right``: ``a (..., n, n)`` (a Gram matrix ``JᵀJ``), ``start (..., n, k)``,
  attributes ``iterations``, ``sweeps`` (int32) and ``shift`` (f64) -> the right
  singular vector of ``J``'s smallest singular value, ``(..., n)``: every step of
  :func:`linkopt._engine.singularity.smallest_right_vectors` after the Gram matrix
  (``k`` at most ``_dense.smallest_max_k()``, 32);
* ``normal_equations``: ``rows (..., m, 14)``, ``c (..., m)``, attribute ``pairs``
  (int32, ``2 m``) -> ``(JᵀJ (..., n, n), Jᵀc (..., n))`` of the ``J`` whose row ``r``
  is ``rows[r, :7]`` in body ``pairs[2r]``'s 7 columns and ``rows[r, 7:]`` in body
  ``pairs[2r + 1]``'s (``-1``: no body), ``n`` 7 per body: the constraint solves'
  normal equations from their two-body row blocks
  (:func:`linkopt._engine.dense.block_normal`);
* ``band_factor``: ``band (..., B, w + 1, 7, 7)``, ``d (...)`` -> the lower block
  Cholesky factor of ``band + d I`` in the same block-band storage
  (``band[i, k] = H[i, i - k]``; :mod:`linkopt._engine.band_factor`);
* ``band_solve``: that factor ``L (..., B, w + 1, 7, 7)``, ``b (..., B, 7)``,
  attribute ``mode`` as ``tri_solve``'s -> ``x (..., B, 7)``; each batch dimension of
  ``L`` and ``b`` is 1 or the result's (one factor serves many right-hand sides);
* ``band_normal``: ``rows (..., m, 14)``, ``c (..., m)``, attribute ``pairs`` as
  ``normal_equations``' but naming block rows of the band (``|pairs[2r] -
  pairs[2r + 1]| <= w``) -> ``(JᵀJ (..., B, w + 1, 7, 7), Jᵀc (..., B, 7))`` in
  ``band_factor``'s storage (:func:`linkopt._engine.banded.normal_equations`);
* ``arrow_normal``: the same for a band with ``h`` hub bodies last
  (:mod:`linkopt._engine.arrowhead`) -> the others' band ``(..., n, w + 1, 7, 7)``,
  the border ``(..., n, h, 7, 7)`` (``H[hub j, body i]``), the corner ``(..., h, h,
  7, 7)`` (both triangles) and ``Jᵀc (..., n + h, 7)``.

JAX-free: importing this module imports neither JAX nor the extension.
"""

from __future__ import annotations

import hashlib
import importlib
import importlib.util
import os
import re
import warnings
from pathlib import Path
from types import ModuleType

#: The ABI version of the handlers this code expects (``kVersion`` in ``dense.cc``); an
#: extension of another version (a stale build) is not used.
VERSION = 5
#: The environment variable that turns the kernels off when set to ``0``.
ENVIRONMENT = "LINKOPT_KERNELS"
#: The handlers' names, the keys of :func:`handlers`.
NAMES = (
    "cholesky",
    "tri_solve",
    "lower_inverse",
    "damped_solve",
    "smallest_right",
    "normal_equations",
    "band_factor",
    "band_solve",
    "band_normal",
    "arrow_normal",
)
SOURCE = Path(__file__).with_name("dense.cc")
#: How to rebuild the extension against the running jaxlib (in every refusal's warning).
REBUILD = (
    "rebuild it against the installed jaxlib: `pip install --no-build-isolation "
    "--no-deps --force-reinstall <linkopt source or sdist>`, or `python setup.py "
    "build_ext --inplace` in a source checkout"
)


class KernelsWarning(RuntimeWarning):
    """The compiled kernels are built but cannot be used with this jaxlib: linkopt
    runs its plain-JAX code (the same results to round-off, slower)."""


#: Why the latest :func:`handlers` returned None; None after it returned the handlers.
reason: str | None = "handlers() not called yet"

_module: ModuleType | None = None
_load_error: str | None = None
_loaded = False
#: Why XLA (or the FFI check) refused the extension: set once, then never used again.
_refused: str | None = None


def disabled() -> bool:
    """Whether ``$LINKOPT_KERNELS`` turns the kernels off (``0``, ``false``, ``no``,
    ``off``)."""
    return os.environ.get(ENVIRONMENT, "").strip().lower() in (
        "0",
        "false",
        "no",
        "off",
    )


def _load() -> ModuleType | None:
    """The extension module, imported once per process; None if it cannot be used."""
    global _module, _load_error, _loaded
    if not _loaded:
        _loaded = True
        try:
            module = importlib.import_module(f"{__name__}._dense")
            version = module.version()
        except ModuleNotFoundError:
            _load_error = (
                "linkopt was installed without its compiled kernels (no C++ compiler "
                "or no XLA FFI headers when it was built)"
            )
        except Exception as exc:
            _load_error = f"{__name__}._dense failed to load: {exc!r}"
        else:
            if version == VERSION:
                _module = module
            else:
                _load_error = (
                    f"{__name__}._dense has handler version {version}, this linkopt "
                    f"expects {VERSION} (a stale build: reinstall linkopt)"
                )
        if _module is not None and (why := _ffi_mismatch(_module)) is not None:
            refuse(why)
    return _module


def running_ffi_api_version() -> tuple[int, int] | None:
    """``(major, minor)`` of the XLA FFI API of the installed jaxlib, read from its
    ``include/xla/ffi/api/c_api.h`` (None where jaxlib or the header is missing)."""
    spec = importlib.util.find_spec("jaxlib")
    if spec is None or not spec.submodule_search_locations:
        return None
    for folder in spec.submodule_search_locations:
        header = Path(folder, "include", "xla", "ffi", "api", "c_api.h")
        if header.is_file():
            return header_ffi_api_version(header.read_text(errors="replace"))
    return None


def header_ffi_api_version(text: str) -> tuple[int, int] | None:
    """``(XLA_FFI_API_MAJOR, XLA_FFI_API_MINOR)`` as ``c_api.h``'s text defines them."""
    found = [
        re.search(rf"^\s*#\s*define\s+XLA_FFI_API_{part}\s+(\d+)", text, re.M)
        for part in ("MAJOR", "MINOR")
    ]
    if None in found:
        return None
    return int(found[0].group(1)), int(found[1].group(1))


def running_jaxlib_version() -> str | None:
    """The installed jaxlib's version, from its package metadata (no import)."""
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("jaxlib")
    except PackageNotFoundError:
        return None


def ffi_compatible(built: tuple[int, int], running: tuple[int, int] | None) -> bool:
    """Whether XLA of FFI API ``running`` registers handlers built against ``built``:
    the same major version, a minor version no newer (unknown ``running``: assumed)."""
    if running is None:
        return True
    return built[0] == running[0] and built[1] <= running[1]


def _ffi_mismatch(module: ModuleType) -> str | None:
    """Why the extension cannot be registered with the running jaxlib, or None."""
    built = tuple(module.ffi_api_version())
    running = running_ffi_api_version()
    if ffi_compatible(built, running):
        return None
    return (
        f"{__name__}._dense was built against XLA FFI API {built[0]}.{built[1]} "
        f"(jaxlib {_built_jaxlib(module) or 'unknown'}), which the installed jaxlib "
        f"{running_jaxlib_version() or ''} (XLA FFI API {running[0]}.{running[1]}) "
        "cannot load"
    )


def _built_jaxlib(module: ModuleType) -> str | None:
    """The jaxlib the extension was built with (None for builds that predate it)."""
    read = getattr(module, "jaxlib_version", None)
    return (read() or None) if read is not None else None


def refuse(why: str) -> None:
    """Stop using the extension in this process (``why``: the refusal, e.g. XLA's
    error from registering a handler): :func:`handlers` returns None from now on, with
    ``why`` as :data:`reason`, and one :class:`KernelsWarning` says so."""
    global _refused, reason
    if _refused is not None:
        return
    _refused = reason = why
    warnings.warn(
        f"linkopt's compiled kernels are not used: {why}. linkopt runs its plain-JAX "
        f"code instead (the same results to round-off, slower); {REBUILD}.",
        KernelsWarning,
        stacklevel=2,
    )


def handlers() -> dict[str, object] | None:
    """:data:`NAMES` -> each handler's PyCapsule, or None (never an exception) when
    the extension is missing, fails to load, is of another :data:`VERSION` or
    ``$LINKOPT_KERNELS`` is ``0``; :data:`reason` then says which."""
    global reason
    if disabled():
        reason = f"turned off by {ENVIRONMENT}={os.environ[ENVIRONMENT]}"
        return None
    module = _load()
    if module is None:
        reason = _load_error
        return None
    if _refused is not None:
        reason = _refused
        return None
    try:
        capsules = dict(module.capsules())
    except Exception as exc:
        reason = f"{__name__}._dense.capsules() failed: {exc!r}"
        return None
    reason = None
    return capsules


def source_sha256() -> str | None:
    """SHA-256 of the ``dense.cc`` the extension was built from (None without it)."""
    module = _load()
    return None if module is None else module.source_sha256() or None


def stale() -> bool:
    """Whether the extension was built from another ``dense.cc`` than the one beside
    this file (an editable install whose source changed since it was built)."""
    built = source_sha256()
    if built is None or not SOURCE.exists():
        return False
    return hashlib.sha256(SOURCE.read_bytes()).hexdigest() != built


def digest() -> str:
    """Hex digest of what a compiled program that may call the handlers depends on:
    whether they are used (availability and ``$LINKOPT_KERNELS``) and, when they are,
    the ``dense.cc`` text they were built from, their version and the XLA FFI API
    version of their headers."""
    parts = [f"linkopt-kernels {VERSION}"]
    if handlers() is None:
        parts.append("unavailable")
    else:
        module = _load()
        built = module.source_sha256() or (
            hashlib.sha256(SOURCE.read_bytes()).hexdigest() if SOURCE.exists() else ""
        )
        parts += ["available", str(module.version()), built]
        parts.append(".".join(map(str, module.ffi_api_version())))
    return hashlib.sha256("|".join(parts).encode()).hexdigest()


def max_n() -> int | None:
    """The largest matrix order the handlers take (None without the extension)."""
    module = _load()
    return None if module is None else module.max_n()


def damped_max_n() -> int | None:
    """The largest matrix order ``damped_solve`` takes (None without the extension)."""
    module = _load()
    return None if module is None else module.damped_max_n()


def smallest_max_k() -> int | None:
    """The widest start block ``smallest_right`` takes (None without the
    extension)."""
    module = _load()
    return None if module is None else module.smallest_max_k()


def info() -> dict[str, object]:
    """What a diagnostic prints: availability, :data:`reason`, versions (the handlers',
    and the XLA FFI API and jaxlib of the build and of this process), staleness."""
    available = handlers() is not None
    module = _load()
    return {
        "available": available,
        "path": "compiled kernels" if available else "plain JAX",
        "reason": reason,
        "version": VERSION,
        "extension_version": None if module is None else module.version(),
        "max_n": max_n(),
        "damped_max_n": damped_max_n(),
        "smallest_max_k": smallest_max_k(),
        "ffi_api_version": None if module is None else module.ffi_api_version(),
        "built_jaxlib": None if module is None else _built_jaxlib(module),
        "running_ffi_api_version": running_ffi_api_version(),
        "running_jaxlib": running_jaxlib_version(),
        "stale": stale(),
        "digest": digest(),
    }
