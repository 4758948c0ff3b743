"""Traced programs kept on disk (:mod:`jax.export`), so that a warm process skips
tracing.

JAX's persistent compilation cache (:mod:`linkopt._config`) keeps compiled executables,
but to look one up a new process must first trace and lower the Python function, which
for the batched evaluation costs more than loading the executable (figures in
``benchmarks/bench_evaluation.py``), in every optimiser run and worker process. The
evaluation, the partial gradient, the blocked solves, σ_min and read-outs of concrete
arrays and the load-time rest checks all run through :func:`call`: the warm main
command spent 5.8 s of 61.5 s tracing before the solves did (0.05 s after, 47.4 s in
all; ``benchmarks/bench_compile.py``).
:func:`call` serialises the traced program (StableHLO) under a key of everything it
depends on: the program's name, the mechanism's fingerprint
(:func:`linkopt._engine.model.fingerprint`: its contents, the file path left out), the
argument shapes and dtypes, the jax version and the source of every module of the
package, subfolders included (:func:`source_digest`). A later process deserialises it
instead of tracing. The entry is written to a temporary file and renamed, so worker
processes can share the directory, and the folder is kept under its size limit with
least-recently-used eviction (:mod:`linkopt._cache`). An entry that cannot be read is
traced again and rewritten. A program that cannot be exported (a custom call that jax
does not guarantee stable) runs through plain ``jax.jit``, with a warning once per
process (:data:`UNEXPORTED`).
"""

from __future__ import annotations

import hashlib
import warnings
import weakref
from collections.abc import Callable
from functools import cache
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
from jax import export

from .._cache import read_used, store
from .._config import cache_directory, jit
from .model import Mechanism, fingerprint

#: The package folder whose sources key every program (:func:`source_digest`).
PACKAGE = Path(__file__).resolve().parents[1]
#: This process's programs: mechanism → ``(name, argument signature)`` → jitted call
#: of the (de)serialised program. Weak in the mechanism, so a mechanism that nothing
#: else holds (an earlier verification round's) is freed with its programs.
PROGRAMS: weakref.WeakKeyDictionary[Mechanism, dict[tuple, Callable]] = (
    weakref.WeakKeyDictionary()
)
#: Names of the programs that could not be exported or serialised in this process.
UNEXPORTED: set[str] = set()


def source_digest(package: Path) -> str:
    """Hex digest of the jax version and every ``.py`` file under ``package``, in every
    subfolder, by path relative to ``package`` and content: an edit anywhere in the
    package keys new programs instead of reusing stale ones."""
    sink = hashlib.sha256(jax.__version__.encode())
    for path in sorted(package.rglob("*.py")):
        sink.update(path.relative_to(package).as_posix().encode())
        sink.update(path.read_bytes())
    return sink.hexdigest()


@cache
def _package_digest(package: Path) -> str:
    """:func:`source_digest`, once per process: its modules are loaded already."""
    return source_digest(package)


def _spec(leaf) -> jax.ShapeDtypeStruct:
    return jax.ShapeDtypeStruct(np.shape(leaf), jnp.asarray(leaf).dtype)


def _dtype(leaf) -> str:
    """A leaf's dtype without moving it to the device (a Python number as JAX would
    take it: ``float64``/``int64`` with x64 on)."""
    dtype = getattr(leaf, "dtype", None)
    return np.dtype(dtype if dtype is not None else np.asarray(leaf).dtype).str


def _signature(args) -> tuple:
    """The tree structure, shapes and dtypes of ``args``: what a program depends on
    besides its name, mechanism and the sources (cheap and hashable, so the blocked
    solves can look their program up on every block)."""
    leaves, tree = jax.tree_util.tree_flatten(args)
    return tree, tuple((np.shape(leaf), _dtype(leaf)) for leaf in leaves)


def _key(name: str, mech: Mechanism, signature: tuple) -> str:
    tree, leaves = signature
    sink = hashlib.sha256(
        f"{name}|{_package_digest(PACKAGE)}|{fingerprint(mech)}".encode()
    )
    sink.update(str(tree).encode())
    for shape, dtype in leaves:
        sink.update(f"{dtype}{shape}".encode())
    return sink.hexdigest()


def _directory() -> Path:
    return cache_directory() / "traces"


def _load(path: Path):
    blob = read_used(path)
    if blob is None:
        return None
    try:
        return export.deserialize(bytearray(blob))
    except Exception:  # truncated or from an incompatible jax: trace again
        return None


def _store(path: Path, exported) -> None:
    try:
        blob = exported.serialize()
    except Exception as err:  # e.g. an unregistered pytree node: kept in memory
        _warn(path.name.split("-")[0], "serialised", err)
        return
    store("traces", path, bytes(blob))


def _warn(name: str, what: str, err: Exception) -> None:
    """One warning per program name and process: a program that cannot be exported
    or serialised is traced again by every process (slower, not wrong)."""
    if name in UNEXPORTED:
        return
    UNEXPORTED.add(name)
    warnings.warn(
        f"linkopt program {name!r} could not be {what} ({type(err).__name__}: "
        f"{err}); it is traced again in every process",
        RuntimeWarning,
        stacklevel=4,
    )


def _named(name: str, fn: Callable) -> Callable:
    """``fn`` under ``name``, which JAX's compile events and errors then show."""

    def program(*args):
        return fn(*args)

    program.__name__ = program.__qualname__ = name
    return program


def _program(name: str, mech: Mechanism, fn: Callable, args) -> Callable:
    signature = _signature(args)
    memo = PROGRAMS.setdefault(mech, {})
    if (name, signature) in memo:
        return memo[name, signature]
    key = _key(name, mech, signature)
    path = _directory() / f"{name}-{key[:32]}.jaxexport"
    exported = _load(path)
    if exported is None:
        specs = jax.tree_util.tree_map(_spec, args)
        try:
            exported = export.export(jax.jit(fn))(*specs)
        except Exception as err:  # not exportable: plain jit, traced in every process
            _warn(name, "exported", err)
            memo[name, signature] = jit(_named(name, fn))
            return memo[name, signature]
        _store(path, exported)
    memo[name, signature] = jit(_named(name, exported.call))
    return memo[name, signature]


def call(name: str, mech: Mechanism, fn: Callable, *args):
    """``jit(fn)(*args)``, with ``fn``'s trace read from (or written to) the disk
    cache.

    ``fn`` must be a pure function of array arguments that depends on nothing but
    ``mech``, the linkopt sources and its arguments; ``name`` names the program."""
    return _program(name, mech, fn, args)(*args)
