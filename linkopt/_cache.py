"""linkopt's on-disk caches, each bounded in size with least-recently-used eviction,
used where the user asks for them (:func:`linkopt.use_cache`; the command line always
asks).

Two kinds live under :func:`cache_directory` (``$LINKOPT_CACHE_DIR``, else
``$XDG_CACHE_HOME/linkopt/jax``, default ``~/.cache/linkopt/jax``):

* **executables**: JAX's persistent compilation cache, files
  ``executables/<key>-cache`` with their last use in ``<key>-atime``, written, read
  and evicted by JAX itself
  (``jax_compilation_cache_max_size`` set to this kind's share, which makes JAX
  take a file lock around every read and write, so processes sharing the folder never
  read a half-written entry; a folder of its own, since JAX's eviction fails on an
  entry without its last-use file, as an older linkopt wrote them beside it);
* **traces**: the traced programs of :mod:`linkopt._engine.programs`, files
  ``traces/<name>-<key>.jaxexport``, written here.

A trace is written through :func:`linkopt._folders.write_atomic`, without its fsync
(an entry lost in a power cut is computed again): into a temporary file in its folder,
named so that no pattern of :data:`PATTERNS` matches it
(``.linkopt-tmp-…-NAME.partial``: never counted, evicted or read as an entry), then
renamed into place. Each read sets the entry's modification time, its last use. After
a write, the oldest entries are removed until the folder holds at most its share of
``$LINKOPT_CACHE_SIZE_MB`` megabytes (default :data:`DEFAULT_MB`): :data:`SHARES`. A
reader that finds its entry gone traces or compiles again.

This module imports no JAX: the command line records its request here
(:func:`request`) before it knows whether it will compute, and
:mod:`linkopt._config` applies it when JAX is first set up for linkopt.
"""

from __future__ import annotations

import contextlib
import importlib.util
import os
import warnings
from dataclasses import dataclass
from pathlib import Path

from . import _folders as folders
from ._errors import InputError

#: Total size of the caches when ``$LINKOPT_CACHE_SIZE_MB`` is not set, in megabytes.
DEFAULT_MB = 1024
#: The share of the total that each kind may hold.
SHARES = {"executables": 0.75, "traces": 0.25}
#: File name patterns of each kind's entries, and its folder under the cache directory.
PATTERNS = {"executables": "*-cache", "traces": "*.jaxexport"}
FOLDERS = {"executables": "executables", "traces": "traces"}


def cache_directory() -> Path:
    """Directory of linkopt's caches for this user."""
    explicit = os.environ.get("LINKOPT_CACHE_DIR")
    if explicit:
        return Path(explicit)
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "linkopt" / "jax"


def total_limit() -> int:
    """``$LINKOPT_CACHE_SIZE_MB`` in bytes (:data:`DEFAULT_MB` when unset)."""
    text = os.environ.get("LINKOPT_CACHE_SIZE_MB")
    if text is None:
        return DEFAULT_MB * 2**20
    try:
        value = float(text)
    except ValueError:
        value = float("nan")
    if not 1.0 <= value <= 2**30:
        raise InputError(
            f"LINKOPT_CACHE_SIZE_MB: expected a size in megabytes from 1 to 2^30, "
            f"got {text!r}"
        )
    return int(value * 2**20)


def limit(kind: str) -> int:
    """The most bytes that ``kind`` ("executables" or "traces") may hold."""
    return int(SHARES[kind] * total_limit())


def folder(kind: str) -> Path:
    return (cache_directory() / FOLDERS[kind]).resolve()


def read_used(path: Path) -> bytes | None:
    """The bytes of ``path``, its modification time set to now (its last use); None
    when it is missing."""
    try:
        blob = path.read_bytes()
    except FileNotFoundError:
        return None
    try:
        os.utime(path)
    except OSError:
        pass  # gone meanwhile, or a read-only cache: the read stands
    return blob


@dataclass(frozen=True)
class Entry:
    path: Path
    size: int
    used: float  # modification time: last write or read


def entries(kind: str) -> list[Entry]:
    """``kind``'s entries, least recently used first."""
    found = []
    for path in folder(kind).glob(PATTERNS[kind]):  # no temporary file matches
        try:
            stat = path.stat()
        except FileNotFoundError:
            continue  # removed by another process meanwhile
        found.append(Entry(path, stat.st_size, _last_use(path, stat.st_mtime)))
    return sorted(found, key=lambda e: e.used)


def _atime_path(path: Path) -> Path | None:
    """An executable's last-use file (JAX's), None for a trace."""
    if not path.name.endswith("-cache"):
        return None
    return path.with_name(path.name.removesuffix("-cache") + "-atime")


def _last_use(path: Path, modified: float) -> float:
    """An entry's last use in seconds: JAX's last-use file of an executable, else its
    modification time."""
    atime = _atime_path(path)
    try:
        return int.from_bytes(atime.read_bytes(), "little") / 1e9 if atime else modified
    except OSError:
        return modified


def trim(kind: str, keep: int | None = None) -> int:
    """Remove ``kind``'s least recently used entries until it holds at most ``keep``
    bytes (its :func:`limit` by default); the number removed."""
    keep = limit(kind) if keep is None else keep
    with _locked(kind):
        found = entries(kind)
        total = sum(e.size for e in found)
        removed = 0
        for entry in found:
            if total <= keep:
                break
            entry.path.unlink(missing_ok=True)
            if (atime := _atime_path(entry.path)) is not None:
                atime.unlink(missing_ok=True)
            total -= entry.size
            removed += 1
    return removed


@contextlib.contextmanager
def _locked(kind: str):
    """JAX's lock of the executables' folder (``.lockfile``, taken by JAX around each
    read and write), held while they are trimmed; nothing for the traces, or without
    ``filelock``."""
    try:
        import filelock
    except ImportError:
        filelock = None
    if kind != "executables" or filelock is None or not folder(kind).is_dir():
        yield
        return
    with filelock.FileLock(folder(kind) / ".lockfile"):
        yield


def store(kind: str, path: Path, blob: bytes) -> None:
    """Write one entry atomically, then trim the kind to its limit; a cache that
    cannot be written is left as it is (the caller keeps its result in memory). With
    an invalid ``$LINKOPT_CACHE_SIZE_MB`` the entry is written, nothing is trimmed, and
    a warning says why (``linkopt cache info`` names the error)."""
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        folders.write_atomic(path, blob, durable=False)
    except OSError:
        return
    try:
        trim(kind)
    except InputError as err:
        warnings.warn(f"linkopt cache not trimmed: {err}", RuntimeWarning, stacklevel=2)
    except OSError:
        pass


def info() -> dict:
    """Folder, entries, bytes and limit of each kind, and whether JAX can bound its
    executables (its eviction needs the ``filelock`` package)."""
    return {
        "directory": str(cache_directory()),
        "bounded_executables": info_bounded(),
        "kinds": {
            kind: {
                "folder": str(folder(kind)),
                "entries": len(found := entries(kind)),
                "bytes": sum(e.size for e in found),
                "limit_bytes": limit(kind),
            }
            for kind in SHARES
        },
    }


def clear() -> dict[str, int]:
    """Remove every entry of both kinds (and temporary files left by killed
    writers); the number removed per kind."""
    removed = {kind: trim(kind, keep=0) for kind in SHARES}
    for kind in SHARES:
        for stray in folder(kind).glob(f"{folders.TEMP_PREFIX}*"):
            stray.unlink(missing_ok=True)
    for stray in folder("executables").glob("*-atime"):  # their entries are gone
        stray.unlink(missing_ok=True)
    for old in cache_directory().glob(PATTERNS["executables"]):  # an older layout's
        old.unlink(missing_ok=True)
        removed["executables"] += 1
    return removed


# --- which caches are in use ---------------------------------------------------------


@dataclass(frozen=True)
class Use:
    """The caches asked for: in ``directory``, or where :func:`cache_directory` points
    at each use (``None``). Pickled into spawned worker processes, which use it too."""

    directory: str | None = None

    def root(self) -> Path:
        return Path(self.directory) if self.directory else cache_directory()


#: The caches this process was asked to use (:func:`request`), or None.
_USE: Use | None = None


def request(directory: str | os.PathLike | None = None) -> Use:
    """Record that this process uses the caches (in ``directory``, by default
    :func:`cache_directory`); JAX is configured for them by
    :func:`linkopt._config.use_cache`, at once or when linkopt first sets JAX up."""
    global _USE
    _USE = Use(None if directory is None else str(directory))
    return _USE


def request_none() -> None:
    """Record that this process uses no caches (their folder cannot be made)."""
    global _USE
    _USE = None


def info_bounded() -> bool:
    """Whether JAX can bound the executables (its eviction needs ``filelock``)."""
    return importlib.util.find_spec("filelock") is not None


def requested() -> Use | None:
    """The caches this process uses, or None where nobody asked."""
    return _USE


def traces_folder() -> Path | None:
    """The folder of the traced programs, or None where the caches are not in use."""
    return None if _USE is None else (_USE.root() / FOLDERS["traces"]).resolve()


def mark_executables(directory: Path) -> int:
    """Give each executable without a last-use file one (its modification time), so
    that JAX's eviction can rank it (JAX fails on an entry without one, e.g. written by
    a linkopt that predates its eviction); the number marked."""
    marked = 0
    for path in directory.glob(PATTERNS["executables"]):
        atime = path.with_name(path.name.removesuffix("-cache") + "-atime")
        if atime.exists():
            continue
        try:
            stamp = int(path.stat().st_mtime * 1e9)
            atime.write_bytes(stamp.to_bytes(8, "little"))
        except OSError:
            continue
        marked += 1
    return marked
