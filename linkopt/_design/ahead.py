"""Worker processes spawned before their mechanism exists, without importing JAX here.

A worker's start-up is a Python and JAX import, which an optimiser's first iteration
would otherwise wait for. :func:`start` spawns the ``count - 1``
worker processes of a :class:`linkopt._design.workers.Workers` of ``count`` processes
at once, so that they import while the caller loads and checks the mechanism
(``linkopt optimize`` calls it before loading the file); the next ``Workers`` of as many
processes adopts them (:func:`adopt`), and :func:`close` ends them where none does (a
file that fails to load, a finished run resumed). After :func:`start`, a ``Workers``
that finishes hands its processes back (:func:`keep`) instead of ending them: the next
round's ``Workers`` adopts them, or the run's final outputs take one for the work they
do beside this process (:func:`side`; :mod:`linkopt._design.run`), warm, with JAX
imported and the evaluation's programs loaded. A job handed to :func:`early` (the
final outputs' part that does not depend on the run: the file's design's space
plot) starts in the first process held that way, while this one runs the
run's last verification round, where that process would otherwise wait; its future is
:func:`early_result`'s. This module imports neither JAX nor the engine, so that the
processes start before the caller's own imports.
"""

from __future__ import annotations

import importlib
import multiprocessing
from collections.abc import Callable
from concurrent.futures import Future, ProcessPoolExecutor
from concurrent.futures.process import BrokenProcessPool

from .. import _cache

#: Processes spawned by :func:`start`, not adopted yet, with the ``count`` they serve.
_AHEAD: tuple[int, ProcessPoolExecutor] | None = None
#: Whether a finished ``Workers`` hands its processes back here (:func:`keep`): in a
#: process that called :func:`start` (the command line), which :func:`close` ends.
_KEEP = False
#: Modules a held process imports as soon as it is held (:func:`start`'s ``warm``).
_WARM: tuple[str, ...] = ()
#: The job of :func:`early` (function, arguments), and its future once submitted.
_EARLY: tuple[Callable, tuple] | None = None
#: Keyword arguments the job gets too (:func:`early_given`).
_GIVEN: dict = {}
_FUTURE: Future | None = None


def initialise(caches: _cache.Use | None = None) -> None:
    """A worker process's start-up: the caches its parent uses (``caches``), the
    imports, and OpenBLAS held to one thread for its lifetime
    (:mod:`linkopt._config`)."""
    from .._config import adopt, one_blas_thread

    adopt(caches)
    from . import evaluation, partial  # noqa: F401  (the imports are the start-up)

    one_blas_thread()


def _ready() -> None:
    """A task that only makes the pool spawn a process (:func:`start`)."""


def spawn(count: int) -> ProcessPoolExecutor:
    """A pool of ``count`` worker processes (spawn, not fork: fork would copy JAX's
    threads)."""
    return ProcessPoolExecutor(
        count,
        mp_context=multiprocessing.get_context("spawn"),
        initializer=initialise,
        initargs=(_cache.requested(),),
    )


def start(count: int, warm: tuple[str, ...] = ()) -> None:
    """Spawn the ``count - 1`` worker processes of a ``Workers`` of ``count`` now;
    nothing for ``count`` < 2 or when some are spawned already. ``warm``: modules (by
    name: the caller's layer knows what its outputs draw with) that a process held by
    :func:`keep` imports while this one works on (a run's last verification round)."""
    global _AHEAD, _KEEP, _WARM
    if count < 2 or _AHEAD is not None:
        return
    _KEEP, _WARM = True, tuple(warm)
    pool = spawn(count - 1)
    for _ in range(count - 1):  # each submit to a pool with no idle process spawns one
        pool.submit(_ready)
    _AHEAD = (count, pool)


def adopt(count: int) -> ProcessPoolExecutor | None:
    """The processes of :func:`start` if they serve ``count`` (and are then no longer
    held here), else None."""
    global _AHEAD
    if _AHEAD is None or _AHEAD[0] != count:
        return None
    pool, _AHEAD = _AHEAD[1], None
    return pool


def keep(count: int, pool: ProcessPoolExecutor) -> bool:
    """Hold the processes of a finished ``Workers`` of ``count`` for the next one, or
    for :func:`side` (the run's final outputs): their imports and loaded programs are
    what a fresh process would spend its first seconds on. Only after :func:`start`
    and while nothing is held; False: not held, the caller ends them."""
    global _AHEAD, _FUTURE
    if not _KEEP or _AHEAD is not None:
        return False
    _AHEAD = (count, pool)
    try:
        if _WARM:
            pool.submit(_import, _WARM)
        if _EARLY is not None and _FUTURE is None:
            _FUTURE = pool.submit(_EARLY[0], *_EARLY[1], **_GIVEN)
    except (BrokenProcessPool, RuntimeError):  # its next user replaces it
        pass
    return True


def early(fn: Callable, *args) -> None:
    """Have the first process that :func:`keep` holds run ``fn(*args)`` (a module-level
    function, to pickle) once, as soon as it is held, after :func:`start`'s ``warm``
    imports; a pool that adopts the process later queues its tasks behind it. Nothing
    runs without :func:`start` (the library's runs hold no process)."""
    global _EARLY
    _EARLY = (fn, args)
    _GIVEN.clear()


def early_given(**kwargs) -> None:
    """Keyword arguments for :func:`early`'s job, found after it was asked for (the
    run's evaluation of the file's design, :func:`linkopt._design.run.optimize`),
    if it has not started; the caller's :func:`early_result` check compares the
    positional arguments only, so these must be what the job would compute itself."""
    if _EARLY is not None and _FUTURE is None:
        _GIVEN.update(kwargs)


def early_result() -> tuple[tuple, Future] | None:
    """The arguments and the future of :func:`early`'s job, if it started (and then no
    longer held here: the caller checks that the arguments are the ones it would pass,
    and waits for the result), else None."""
    global _EARLY, _FUTURE
    if _EARLY is None or _FUTURE is None:
        return None
    (_, args), future = _EARLY, _FUTURE
    _EARLY = _FUTURE = None
    _GIVEN.clear()
    return args, future


def _import(names: tuple[str, ...]) -> None:
    """A held process's task: import ``names`` (:func:`start`'s ``warm``)."""
    for name in names:
        importlib.import_module(name)


def side() -> ProcessPoolExecutor | None:
    """The held processes, whatever ``count`` they served (and then no longer held
    here), for work beside this process's; None when none are held."""
    global _AHEAD
    if _AHEAD is None:
        return None
    pool, _AHEAD = _AHEAD[1], None
    return pool


def close() -> None:
    """End the processes of :func:`start` (or :func:`keep`) that nothing adopted."""
    global _AHEAD, _KEEP, _WARM, _EARLY, _FUTURE
    _KEEP, _WARM, _EARLY, _FUTURE = False, (), None, None
    _GIVEN.clear()
    if _AHEAD is not None:
        _AHEAD[1].shutdown(wait=False, cancel_futures=True)
        _AHEAD = None
