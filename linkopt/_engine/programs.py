"""Traced programs kept on disk (:mod:`jax.export`), so that a warm process skips
tracing.

JAX's persistent compilation cache (:mod:`linkopt._config`) keeps compiled executables,
but to look one up a new process must first trace and lower the Python function. For
the batched five-bar evaluation that took 5.9 s, against 2.1 s to load the executable,
and every optimiser run and worker process paid it again. :func:`call` serialises the
traced program (StableHLO) under a key of everything it depends on: the program's name,
a fingerprint of the mechanism's contents (every field but the file path), the argument
shapes and dtypes, the source of every ``linkopt`` module and the jax version. A later
process deserialises it instead of tracing. The entry is written to a temporary file
and renamed, so worker processes can share the directory. An entry that cannot be read
is traced again and rewritten. A program that cannot be exported (a custom call that
jax does not guarantee stable) runs through plain ``jax.jit``.
"""

from __future__ import annotations

import dataclasses
import hashlib
import os
import tempfile
from collections.abc import Callable
from functools import lru_cache
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
from jax import export

from .._config import cache_directory
from .model import Mechanism

_PROGRAMS: dict[str, Callable] = {}  # key → jitted call of the (de)serialised program


def _digest(value, sink) -> None:
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        sink.update(type(value).__name__.encode())
        for f in dataclasses.fields(value):
            if f.name != "source":
                sink.update(f.name.encode())
                _digest(getattr(value, f.name), sink)
    elif isinstance(value, np.ndarray):
        sink.update(f"{value.dtype.str}{value.shape}".encode())
        sink.update(np.ascontiguousarray(value).tobytes())
    elif isinstance(value, (tuple, list)):
        sink.update(f"{type(value).__name__}{len(value)}".encode())
        for item in value:
            _digest(item, sink)
    elif isinstance(value, dict):
        sink.update(f"dict{len(value)}".encode())
        for key in sorted(value, key=str):
            sink.update(repr(key).encode())
            _digest(value[key], sink)
    else:
        sink.update(repr(value).encode())


def fingerprint(mech: Mechanism) -> str:
    """Hex digest of a mechanism's contents (its file path left out)."""
    sink = hashlib.sha256()
    _digest(mech, sink)
    return sink.hexdigest()


@lru_cache(maxsize=1)
def _source_digest() -> str:
    sink = hashlib.sha256(jax.__version__.encode())
    package = Path(__file__).resolve().parents[1]
    for path in sorted(package.rglob("*.py")):
        sink.update(path.relative_to(package).as_posix().encode())
        sink.update(path.read_bytes())
    return sink.hexdigest()


def _spec(leaf) -> jax.ShapeDtypeStruct:
    return jax.ShapeDtypeStruct(np.shape(leaf), jnp.asarray(leaf).dtype)


def _key(name: str, mech: Mechanism, args) -> str:
    sink = hashlib.sha256(f"{name}|{_source_digest()}|{fingerprint(mech)}".encode())
    leaves, tree = jax.tree_util.tree_flatten(args)
    sink.update(str(tree).encode())
    for leaf in leaves:
        sink.update(f"{_spec(leaf).dtype.str}{np.shape(leaf)}".encode())
    return sink.hexdigest()


def _directory() -> Path:
    return cache_directory() / "traces"


def _load(path: Path):
    try:
        return export.deserialize(bytearray(path.read_bytes()))
    except Exception:  # missing, truncated or from an incompatible jax: trace again
        return None


def _store(path: Path, exported) -> None:
    try:
        blob = exported.serialize()
    except Exception:  # e.g. an unregistered pytree node: this process keeps its trace
        return
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        handle, temporary = tempfile.mkstemp(dir=path.parent, suffix=".tmp")
        with os.fdopen(handle, "wb") as stream:
            stream.write(blob)
        os.replace(temporary, path)
    except OSError:
        pass  # read-only cache: this process keeps its trace, later ones trace again


def _program(name: str, mech: Mechanism, fn: Callable, args) -> Callable:
    key = _key(name, mech, args)
    if key in _PROGRAMS:
        return _PROGRAMS[key]
    path = _directory() / f"{name}-{key[:32]}.jaxexport"
    exported = _load(path)
    if exported is None:
        specs = jax.tree_util.tree_map(_spec, args)
        try:
            exported = export.export(jax.jit(fn))(*specs)
        except Exception:  # not exportable: plain jit, traced in every process
            _PROGRAMS[key] = jax.jit(fn)
            return _PROGRAMS[key]
        _store(path, exported)
    _PROGRAMS[key] = jax.jit(exported.call)
    return _PROGRAMS[key]


def call(name: str, mech: Mechanism, fn: Callable, *args):
    """``jax.jit(fn)(*args)``, with ``fn``'s trace read from (or written to) the disk
    cache.

    ``fn`` must be a pure function of array arguments that depends on nothing but
    ``mech``, the linkopt sources and its arguments; ``name`` names the program."""
    return _program(name, mech, fn, args)(*args)
