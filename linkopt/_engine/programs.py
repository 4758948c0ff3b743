"""Traced programs kept on disk (:mod:`jax.export`), so that a warm process skips
tracing, and shared by every mechanism of one structure.

JAX's persistent compilation cache (:mod:`linkopt._config`) keeps compiled executables,
but to look one up a new process must first trace and lower the Python function, which
for the batched evaluation costs more than loading the executable
(``benchmarks/bench_compile.py`` shows both), in every optimiser run and worker
process. The evaluation, the partial gradient, the blocked solves, σ_min and read-outs
of concrete arrays and the load-time rest checks all run through :func:`call`.

A program takes the mechanism as an argument: its numbers (anchors, axes, origins,
output ranges, the design space's map, ...) are the leaves of its pytree and its
:class:`~.structure.Structure` the rest (:mod:`.structure`), with the design padded to
its class (:func:`.lifting.padded`). So its trace and its compiled executable depend
only on the mechanism's structure: a second file of the same structure, or the same
file with other numbers, reuses both. :func:`call` serialises the traced program
(StableHLO) under a key of everything it depends on: the program's name, the
structure (its digest), the argument shapes and dtypes,
the jax version and the source of every module of the package, subfolders included
(:func:`source_digest`). A later process deserialises it instead of tracing. The entry
is written to a temporary file and renamed, so worker processes can share the
directory, and the folder is kept under its size limit with least-recently-used
eviction (:mod:`linkopt._cache`). An entry that cannot be read is traced again and
rewritten. A program that cannot be exported (a custom call that jax does not
guarantee stable) runs through plain ``jax.jit``, with a warning once per process
(:data:`UNEXPORTED`).
"""

from __future__ import annotations

import hashlib
import threading
import warnings
import weakref
from collections.abc import Callable
from functools import cache
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
from jax import export

from .. import _kernels
from .._cache import read_used, store, traces_folder
from .._config import jit
from . import dense
from .lifting import padded
from .model import Mechanism
from .structure import Structure, flatten, unflatten

#: The package folder whose sources key every program (:func:`source_digest`).
PACKAGE = Path(__file__).resolve().parents[1]
#: This process's programs: ``(name, Structure, argument signature)`` → jitted call
#: of the (de)serialised program, least recently used first. Keyed by the structure,
#: which holds no numbers and no names, so it keeps no mechanism alive (an earlier
#: verification round's is freed) and serves every mechanism of one structure.
PROGRAMS: dict[tuple, Callable] = {}
#: Most programs kept loaded (:data:`PROGRAMS`). Each loaded XLA:CPU executable holds
#: its JIT-linked code in a few hundred memory mappings (about 350 for a solve or
#: σ_min program of a small mechanism), and Linux allows a process 65,530
#: (``vm.max_map_count``): past that, XLA aborts ("Unable to allocate section
#: memory") or segfaults while compiling, loading or serialising the next one. A
#: process that kept every program it ever used (a test worker, a notebook going
#: through many mechanisms) crashed so; a program dropped here is loaded again from
#: the disk caches when it is needed again. The five-bar's optimiser uses 9 (7,200
#: mappings in all).
LIVE_PROGRAMS = 48
#: Errors of tracing itself (a traced number used as a constant, :mod:`.lifting`),
#: raised as they are rather than taken for a program that cannot be exported.
TRACE_ERRORS = (
    jax.errors.ConcretizationTypeError,
    jax.errors.TracerArrayConversionError,
    jax.errors.TracerBoolConversionError,
    jax.errors.TracerIntegerConversionError,
)
#: Each mechanism's padded leaves, Structure and leaves' signature (:func:`_numbers`).
NUMBERS: weakref.WeakKeyDictionary[Mechanism, tuple] = weakref.WeakKeyDictionary()
#: Held while a program is looked up or made (:func:`_program`).
_LOCK = threading.RLock()
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
def kernels_digest() -> str:
    """What the compiled kernels contribute to a program (:mod:`.dense`): their
    sources and version when this process uses them, else ``"plain"`` (a trace made
    with them calls their targets, which a process without them cannot run)."""
    return _kernels.digest() if dense.TARGETS is not None else "plain"


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


def _key(name: str, structure: Structure, signature: tuple) -> str:
    (value_tree, value_leaves), (tree, leaves) = signature
    leaves = value_leaves + leaves
    sink = hashlib.sha256(
        f"{name}|{_package_digest(PACKAGE)}|{kernels_digest()}|{structure.key}".encode()
    )
    sink.update(f"{value_tree}|{tree}".encode())
    for shape, dtype in leaves:
        sink.update(f"{dtype}{shape}".encode())
    return sink.hexdigest()


def _trace_path(name: str, structure: Structure, signature: tuple) -> Path | None:
    """Where the trace of program ``name`` for ``structure`` and ``signature`` is
    kept, or None where the caches are not in use (:func:`linkopt.use_cache`)."""
    folder = traces_folder()
    if folder is None:
        return None
    return folder / f"{name}-{_key(name, structure, signature)[:32]}.jaxexport"


def _load(path: Path | None):
    blob = None if path is None else read_used(path)
    if blob is None:
        return None
    try:
        return export.deserialize(bytearray(blob))
    except Exception:  # truncated or from an incompatible jax: trace again
        return None


def _store(path: Path | None, exported) -> None:
    if path is None:
        return
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


def _numbers(mech: Mechanism) -> tuple[list, Structure, tuple]:
    """The leaves and Structure of the mechanism with its design padded
    (:func:`.lifting.padded`), and the leaves' signature; once per mechanism (weakly
    held: :data:`NUMBERS`)."""
    held = NUMBERS.get(mech)
    if held is None:
        leaves, structure = flatten(padded(mech))
        held = NUMBERS[mech] = (leaves, structure, _signature(leaves))
    return held


def _program(name: str, mech: Mechanism, fn: Callable, args) -> Callable:
    """The jitted program, from :data:`PROGRAMS`, the disk or a new trace; one
    thread at a time (:mod:`.blocks` calls programs from several), so that no program
    is loaded twice."""
    with _LOCK:
        return _program_locked(name, mech, fn, args)


def _program_locked(name: str, mech: Mechanism, fn: Callable, args):
    leaves, structure, numbers = _numbers(mech)
    signature = (numbers, _signature(args))
    memo = (name, structure, signature)
    if memo in PROGRAMS:
        PROGRAMS[memo] = PROGRAMS.pop(memo)  # most recently used last
        return PROGRAMS[memo]
    while len(PROGRAMS) >= LIVE_PROGRAMS:  # the least recently used goes
        del PROGRAMS[next(iter(PROGRAMS))]
    path = _trace_path(name, structure, signature)
    exported = _load(path)

    def program(leaves, *args):
        return fn(unflatten(structure, leaves), *args)

    if exported is None:
        specs = jax.tree_util.tree_map(_spec, (leaves, *args))
        try:
            exported = export.export(
                jax.jit(program), disabled_checks=dense.EXPORT_CHECKS
            )(*specs)
        except TRACE_ERRORS:
            raise  # the function itself cannot be traced: no fallback would run it
        except Exception as err:  # not exportable: plain jit, traced in every process
            _warn(name, "exported", err)
            PROGRAMS[memo] = jit(_named(name, program))
            return PROGRAMS[memo]
        _store(path, exported)
    PROGRAMS[memo] = jit(_named(name, exported.call))
    return PROGRAMS[memo]


def stored(name: str, mech: Mechanism, *args) -> bool:
    """Whether the trace of ``call(name, mech, fn, *args)`` is on disk, i.e.
    some process has traced (and so, almost always, compiled) that program before."""
    _, structure, numbers = _numbers(mech)
    path = _trace_path(name, structure, (numbers, _signature(args)))
    return path is not None and path.exists()


def output_shapes(name: str, mech: Mechanism, fn: Callable, *args):
    """The shapes and dtypes (:class:`jax.ShapeDtypeStruct`) of
    ``call(name, mech, fn, *args)``'s result, without running it."""
    leaves = _numbers(mech)[0]
    return jax.eval_shape(_program(name, mech, fn, args), leaves, *args)


def compile_ahead(name: str, mech: Mechanism, fn: Callable, *args) -> None:
    """Compile ``call(name, mech, fn, *args)``'s program for arguments of
    the shapes of ``args`` without running it. The executable goes to the persistent
    compilation cache, where another process that calls the program finds it (an
    optimiser's worker compiles a program that the calling process needs next:
    :mod:`linkopt._design.workers`)."""
    leaves = _numbers(mech)[0]
    _program(name, mech, fn, args).lower(leaves, *args).compile()


def call(name: str, mech: Mechanism, fn: Callable, *args):
    """``jit(fn)(mech, *args)``, with the trace read from (or written to) the disk
    cache and shared by every mechanism of the same structure.

    ``fn(mech, *args)`` must be a pure function of the mechanism and array arguments
    that depends on nothing but them and the linkopt sources; inside it the
    mechanism's numbers are traced and its names blank (:mod:`.structure`). ``name``
    names the program."""
    with _LOCK:
        leaves = _numbers(mech)[0]
        program = _program_locked(name, mech, fn, args)
    return program(leaves, *args)
