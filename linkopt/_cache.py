"""linkopt's on-disk caches, each bounded in size with least-recently-used eviction.

Two kinds live under :func:`cache_directory` (``$LINKOPT_CACHE_DIR``, else
``$XDG_CACHE_HOME/linkopt/jax``, default ``~/.cache/linkopt/jax``):

* **executables**: JAX's persistent compilation cache, files ``<key>-cache`` in the
  folder itself (the names JAX's own cache uses, so entries written by either are
  read by both);
* **traces**: the traced programs of :mod:`linkopt._engine.programs`, files
  ``traces/<name>-<key>.jaxexport``.

Every entry is written through :func:`linkopt._folders.write_atomic`, without its fsync
(an entry lost in a power cut is computed again): into a temporary file in its folder,
named so that no pattern of :data:`PATTERNS` matches it
(``.linkopt-tmp-…-NAME.partial``: never counted, evicted or read as an entry), then
renamed into place, so a process never reads another's half-written entry. Each read
sets the entry's modification time, which is its last use. After a write, the oldest
entries are removed until the folder holds at most its share of
``$LINKOPT_CACHE_SIZE_MB`` megabytes (default :data:`DEFAULT_MB`): :data:`SHARES`. A
reader that finds its entry gone compiles or traces again; nothing else depends on an
entry being there.

JAX's own file cache (``jax._src.lru_cache.LRUCache``) writes entries in place and
evicts only when ``jax_compilation_cache_max_size`` is set, which also takes a lock
around every read and write and refuses entries written without its access-time
files. :func:`install` gives JAX this module's cache instead, through
``jax._src.compilation_cache.get_file_cache``, the one place JAX makes its file cache;
with a JAX that has no such function the executables stay in JAX's own, unbounded
cache (:func:`info` says so).
"""

from __future__ import annotations

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
FOLDERS = {"executables": ".", "traces": "traces"}


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
        found.append(Entry(path, stat.st_size, stat.st_mtime))
    return sorted(found, key=lambda e: e.used)


def trim(kind: str, keep: int | None = None) -> int:
    """Remove ``kind``'s least recently used entries until it holds at most ``keep``
    bytes (its :func:`limit` by default); the number removed."""
    keep = limit(kind) if keep is None else keep
    found = entries(kind)
    total = sum(e.size for e in found)
    removed = 0
    for entry in found:
        if total <= keep:
            break
        entry.path.unlink(missing_ok=True)
        total -= entry.size
        removed += 1
    return removed


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
    """Folder, entries, bytes and limit of each kind, and whether JAX's executables go
    through this module (:func:`install`)."""
    return {
        "directory": str(cache_directory()),
        "bounded_executables": _bounded(),
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
    return removed


# --- JAX's persistent compilation cache ----------------------------------------------


def _executables_class():
    from jax._src.compilation_cache_interface import CacheInterface

    class Executables(CacheInterface):
        """JAX's compilation cache in ``path``: atomic writes, reads that mark use,
        trimmed to :func:`limit` after every write."""

        def __init__(self, path: str):
            self._path = Path(path)

        def get(self, key: str) -> bytes | None:
            return read_used(self._path / f"{key}-cache")

        def put(self, key: str, value: bytes) -> None:
            path = self._path / f"{key}-cache"
            if not path.exists():
                store("executables", path, value)

    return Executables


def _hook():
    """JAX's ``compilation_cache`` module and this module's executables class, or None
    where this JAX has no ``get_file_cache`` to replace."""
    try:
        from jax._src import compilation_cache

        executables = _executables_class()
    except (ImportError, AttributeError):
        return None
    if not callable(getattr(compilation_cache, "get_file_cache", None)):
        return None
    return compilation_cache, executables


def install() -> bool:
    """Make JAX's persistent compilation cache this module's bounded one (before JAX
    first uses its cache); whether this JAX allowed it."""
    hook = _hook()
    if hook is None:
        return False
    compilation_cache, Executables = hook

    def get_file_cache(path: str):
        return Executables(path), path

    get_file_cache.linkopt = True
    compilation_cache.get_file_cache = get_file_cache
    return True


def _bounded() -> bool:
    """Whether JAX's executables go to this module's cache: :func:`install` replaces
    JAX's hook in every process that configures JAX (``linkopt cache info`` does not
    configure JAX, so it asks whether the hook is there to replace)."""
    return _hook() is not None
