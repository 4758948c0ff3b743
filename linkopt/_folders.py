"""Output folders that several processes may point at: checked creation, an exclusive
lock, atomic writes under unique names, and results staged so that they appear together
or not at all.

Used by ``linkopt optimize`` (:mod:`linkopt._design.run`) and by the arm commands that
write a folder (``arm design | simplify | manipulability | trace``); ``plot`` only
checks its folder with :func:`output_folder`.

- :func:`output_folder` creates the folder (and its parents) and checks that files can
  be made in it, so a bad ``--out`` (an existing file, a path inside a file, a folder
  that cannot be created or written) is one :class:`~linkopt.InputError` line before
  any work starts.
- :func:`locked` holds ``flock(LOCK_EX)`` on ``FOLDER/.linkopt.lock`` for a block; the
  file records the holder (``pid N on HOST``), and a second process is refused with an
  :class:`~linkopt.InputError` naming the folder and the holder instead of waiting. The
  kernel drops the lock when its process ends, however it ends (a killed holder leaves
  no stale lock; its file, if left, is taken over). Within one process the lock is
  re-entrant (the CLI holds it across calls that each take it too). The holder removes
  the file before unlocking it, and a taker checks after locking that the file it holds
  is still the one at the path, else it retries: two processes can never each hold a
  different file. Without ``fcntl`` (not POSIX) no lock is taken.
- :func:`write_atomic` writes a hidden temporary file of a unique name (``O_EXCL``) in
  the target's folder, fsyncs it (unless told not to) and renames it over the target,
  so readers see the old or the new file, never a part, and two writers never share a
  temporary file. Every temporary name starts with :data:`TEMP_PREFIX` and ends with
  :data:`TEMP_SUFFIX`, so no pattern that matches a target's name by its end (the
  caches' ``*-cache`` and ``*.jaxexport``, a ``*.csv``) matches a file being written.
- :func:`staged` gives a command a fresh hidden folder (``tempfile.mkdtemp``) inside the
  output folder for the results that belong together. Only when the command's block
  succeeds are they moved in (``os.replace``, each atomic), the *marker* (the summary a
  reader checks first, e.g. ``summary.json``) removed before and moved in last, so a
  folder with a marker holds a complete, matching set. When the block raises, the
  staging folder and everything in it is removed and the folder's previous contents are
  untouched; a staging folder left by a killed process is removed by the next process
  that takes the lock.
"""

from __future__ import annotations

import os
import secrets
import shutil
import socket
import tempfile
import time
from collections.abc import Iterable, Iterator
from contextlib import contextmanager
from pathlib import Path

from ._errors import InputError

try:
    import fcntl
except ImportError:  # pragma: no cover - not POSIX
    fcntl = None

LOCK = ".linkopt.lock"
STAGING_PREFIX = ".linkopt-staging-"
TEMP_PREFIX = ".linkopt-tmp-"
TEMP_SUFFIX = ".partial"

#: realpath of a folder locked by this process -> [lock file descriptor, depth]
_held: dict[str, list[int]] = {}


def _not_a_folder(out: Path) -> str | None:
    """Why ``out`` cannot be a folder (it or a folder above it is a file), or None."""
    for path in (out, *out.parents):
        if path.is_dir():
            return None
        if path.exists() or path.is_symlink():
            return (
                "a file of that name exists"
                if path == out
                else f"{str(path)!r} is a file, not a directory"
            )
    return None


def check_path(path: str | Path, where: str = "--out") -> Path:
    """``path`` as a :class:`Path`; :class:`InputError` when it is an existing file or
    lies inside one (nothing is created)."""
    out = Path(path)
    reason = _not_a_folder(out)
    if reason is not None:
        raise InputError(
            f"{where}: cannot create the output directory {str(out)!r} ({reason}); "
            "expected a writable directory"
        )
    return out


def output_folder(path: str | Path, where: str = "--out") -> Path:
    """The output folder ``path``, created if needed and checked to be writable;
    :class:`InputError` naming ``where`` otherwise (module docstring)."""
    out = check_path(path, where)
    try:
        out.mkdir(parents=True, exist_ok=True)
    except (OSError, ValueError) as err:
        reason = _not_a_folder(out) or getattr(err, "strerror", None) or str(err)
        raise InputError(
            f"{where}: cannot create the output directory {str(out)!r} ({reason}); "
            "expected a writable directory"
        ) from None
    try:
        _temporary(out, "probe").unlink(missing_ok=True)
    except OSError as err:
        raise InputError(
            f"{where}: cannot write to the output directory {str(out)!r} "
            f"({err.strerror or err}); expected a writable directory"
        ) from None
    return out


def _temporary(folder: Path, name: str) -> Path:
    """A new empty file in ``folder``, hidden, of a unique name that holds ``name``
    (for whoever finds one left by a killed writer) between :data:`TEMP_PREFIX` and
    :data:`TEMP_SUFFIX`, with the permissions ``open`` gives."""
    for _ in range(100):
        path = folder / f"{TEMP_PREFIX}{secrets.token_hex(6)}-{name}{TEMP_SUFFIX}"
        try:
            os.close(os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666))
        except FileExistsError:
            continue
        return path
    raise FileExistsError(f"{folder}: no free temporary name for {name}")


def write_atomic(path: str | Path, data: str | bytes, *, durable: bool = True) -> None:
    """Replace ``path`` by a file holding ``data`` (text as UTF-8; module docstring);
    its folder must exist. ``durable=False`` skips the fsync, for files that may be
    lost in a power cut without harm (cache entries, which are computed again)."""
    path = Path(path)
    tmp = _temporary(path.parent, path.name)
    blob = data.encode("utf-8") if isinstance(data, str) else data
    try:
        with open(tmp, "wb") as f:
            f.write(blob)
            if durable:
                f.flush()
                os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


def _holder(fd: int) -> str:
    """What the lock file of another process says about it."""
    for _ in range(20):  # it may not have written its line yet
        text = os.pread(fd, 200, 0).decode("utf-8", "replace").strip()
        if text:
            return text.splitlines()[0]
        time.sleep(0.01)
    return "holder not recorded"


def _same_file(fd: int, path: Path) -> bool:
    try:
        here, there = os.fstat(fd), os.stat(path)
    except FileNotFoundError:
        return False
    return (here.st_dev, here.st_ino) == (there.st_dev, there.st_ino)


def _lock_once(folder: Path, path: Path) -> int | None:
    """The descriptor of ``path``, locked; None when the file was replaced meanwhile."""
    try:
        fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o666)
    except OSError as err:
        raise InputError(
            f"{folder}: cannot create the lock file {LOCK} ({err.strerror or err}); "
            "expected a writable directory"
        ) from None
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        holder = _holder(fd)
        os.close(fd)
        raise InputError(
            f"{folder}: in use by another linkopt process ({holder}); wait for it "
            "to end, or write to another folder"
        ) from None
    except OSError as err:
        os.close(fd)
        raise InputError(
            f"{folder}: cannot lock {LOCK} ({err.strerror or err})"
        ) from None
    if _same_file(fd, path):
        return fd
    os.close(fd)
    return None


def _acquire(folder: Path) -> int:
    path = folder / LOCK
    fd = None
    while fd is None:
        fd = _lock_once(folder, path)
    os.ftruncate(fd, 0)
    os.pwrite(fd, f"pid {os.getpid()} on {socket.gethostname()}\n".encode(), 0)
    _remove_leftovers(folder)
    return fd


def _remove_leftovers(folder: Path) -> None:
    """Staging folders and temporary files of processes that held the lock before and
    were killed (no live process uses them: this one holds the lock)."""
    for entry in folder.iterdir():
        if entry.name.startswith(STAGING_PREFIX) and entry.is_dir():
            shutil.rmtree(entry, ignore_errors=True)
        elif entry.name.startswith(TEMP_PREFIX) and entry.is_file():
            entry.unlink(missing_ok=True)


@contextmanager
def locked(folder: str | Path) -> Iterator[Path]:
    """Hold the exclusive lock on the existing ``folder`` for the block (module
    docstring); :class:`InputError` naming the holder when another process has it."""
    folder = Path(folder)
    if fcntl is None:  # pragma: no cover
        yield folder
        return
    key = os.path.realpath(folder)
    if key in _held:
        _held[key][1] += 1
    else:
        _held[key] = [_acquire(folder), 1]
    try:
        yield folder
    finally:
        _held[key][1] -= 1
        if _held[key][1] == 0:
            fd = _held.pop(key)[0]
            (folder / LOCK).unlink(missing_ok=True)
            os.close(fd)


@contextmanager
def run_folder(path: str | Path, where: str = "--out") -> Iterator[Path]:
    """:func:`output_folder` and :func:`locked` for the block."""
    with locked(output_folder(path, where)) as out:
        yield out


@contextmanager
def staged(folder: Path, marker: str, obsolete: Iterable[str] = ()) -> Iterator[Path]:
    """A fresh staging folder inside ``folder`` for results that belong together; on
    success they replace their namesakes in ``folder``, ``marker`` last, and the files
    named in ``obsolete`` (results of an earlier run the new one does not have) are
    removed with the old marker; on failure nothing in ``folder`` changes (module
    docstring)."""
    stage = Path(tempfile.mkdtemp(prefix=STAGING_PREFIX, dir=folder))
    try:
        yield stage
        names = sorted(p.name for p in stage.iterdir())
        (folder / marker).unlink(missing_ok=True)
        for name in obsolete:
            if name not in names:
                (folder / name).unlink(missing_ok=True)
        for name in sorted(names, key=lambda n: n == marker):
            os.replace(stage / name, folder / name)
    finally:
        shutil.rmtree(stage, ignore_errors=True)
