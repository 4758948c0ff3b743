"""The swarm's particles split over worker processes.

Most of a chunk's work is XLA running one batched program, and much of that program
is serial (loops over Levenberg–Marquardt steps and over the factor's columns), so a
second process keeps a second core busy where XLA's own thread pool cannot.
:class:`Workers` splits the particles into ``count`` contiguous
chunks: the calling process evaluates the first itself while ``count - 1`` spawned
processes, each holding the mechanism, evaluate the others; the chunks' results are
concatenated in particle order. The caller works rather than waits because a spawned
process costs a Python and JAX start-up before its first evaluation, and the caller has
paid that already. Each chunk is the same batched, jitted call as in a single process,
so the persistent compilation cache serves every worker after the first run. A chunk's
numbers do not depend on which process computed it, so a run with the same seed and
worker count always gives the same result. With ``count = 1`` everything runs in the
calling process.

Partial gradients are computed chunk by chunk in the calling process, with the same
chunks and so the same numbers: once its executable is loaded a chunk's gradient costs
far less than loading that executable in every worker would. When the caller has
evaluated its chunk before the workers answer (every first iteration: a worker starts
after the caller), it differentiates that chunk while it waits, so most of the load
falls in time it would have spent idle. ``benchmarks/bench_optimizer.py`` measures the
optimiser with one and two processes (``--workers 1,2``).

On a first run (the evaluation of a chunk never traced on this machine), the calling
process and a worker would each compile the same evaluation side by side and the
caller would then compile the partial gradient alone. Instead the first worker
compiles the partial gradient before its first chunk, while the caller compiles the
evaluation; each then loads the other's executable from the persistent cache. The
numbers do not change; ``benchmarks/bench_optimizer.py`` times the first (cold) run.

A worker's start-up (a Python and JAX import, about a second) can overlap the caller's
own: :mod:`linkopt._design.ahead` spawns the worker processes before the mechanism is
loaded, and the next :class:`Workers` of as many processes adopts them, so that a first
iteration does not wait for their imports. Each task therefore carries its mechanism (a
few kilobytes), which a worker keeps while the next task's has the same fingerprint.

A worker that dies (killed, out of memory, or a crash in XLA) breaks the pool: a new
pool recomputes the chunks that had no result, up to ``RETRIES`` times, and then the
calling process computes them itself, so a lost worker costs time but never hangs or
changes the run (``multiprocessing.Pool`` would wait for ever on the lost task).

OpenBLAS is held to one thread while a chunk computes (:mod:`linkopt._config`): in the
workers for their lifetime, in the calling process only while it computes.
"""

from __future__ import annotations

import dataclasses
from concurrent.futures import Future, ProcessPoolExecutor
from concurrent.futures.process import BrokenProcessPool

import jax
import numpy as np
from jaxtyping import Array, Float

from .._config import one_blas_thread
from .._engine.model import Mechanism, fingerprint
from . import ahead
from .evaluation import Evaluation, alpha_minus, batch_traced_before, evaluate
from .partial import compile_gradient, partial_gradient

RETRIES = 2  # new pools tried after a worker dies, before this process takes over
#: The mechanism of this worker process's latest task, by fingerprint.
_MECHANISM: tuple[str, Mechanism] | None = None


def chunk_slices(n: int, count: int) -> list[slice]:
    """The ``min(count, n)`` contiguous chunks of ``n`` particles, as even as they
    come (the first chunk's size is the batch shape of the evaluation program)."""
    bounds = np.linspace(0, n, min(count, n) + 1).round().astype(int)
    return [slice(a, b) for a, b in zip(bounds[:-1], bounds[1:])]


def _mechanism(key: str, mech: Mechanism) -> Mechanism:
    """The task's mechanism: the one this worker kept if it has the fingerprint
    ``key`` (its programs' numbers are on the device already), else ``mech``."""
    global _MECHANISM
    if _MECHANISM is None or _MECHANISM[0] != key:
        _MECHANISM = (key, mech)
    return _MECHANISM[1]


def _compile_gradients(key: str, mech: Mechanism, sizes: tuple[int, ...]) -> None:
    for rows in sizes:
        compile_gradient(_mechanism(key, mech), rows)


def _evaluate_chunk(key: str, mech: Mechanism, designs: np.ndarray) -> Evaluation:
    return jax.tree_util.tree_map(np.asarray, evaluate(_mechanism(key, mech), designs))


def _evaluate_chunk_here(mech: Mechanism, designs: np.ndarray) -> Evaluation:
    return jax.tree_util.tree_map(np.asarray, evaluate(mech, designs))


def concatenate(parts: list[Evaluation]) -> Evaluation:
    return jax.tree_util.tree_map(lambda *fields: np.concatenate(fields), *parts)


class Workers:
    """``count`` processes (this one and ``count - 1`` spawned) sharing the particles of
    every batched call."""

    def __init__(self, mech: Mechanism, count: int = 1):
        if count < 1:
            raise ValueError(
                f"count must be a positive number of processes, got {count}"
            )
        self.mech = mech
        self.count = count
        self.key = fingerprint(mech)  # a task's mechanism, in the workers
        self._pool = None
        # (designs, evaluation, alpha, gradient) of a first chunk
        self._early: tuple | None = None
        #: The first design of the last :meth:`evaluate` and its evaluation (numpy).
        self.first: tuple[np.ndarray, Evaluation] | None = None
        self.restarts = 0  # worker pools replaced after a worker died
        # a worker's compilation of the partial gradients on a cold start
        self._compiling: Future | None = None
        self._cold_checked = False
        if count > 1:
            self._pool = self._start_pool()

    def _start_pool(self) -> ProcessPoolExecutor:
        """The processes spawned ahead (:mod:`linkopt._design.ahead`), or new ones."""
        return ahead.adopt(self.count) or ahead.spawn(self.count - 1)

    def _task(self, fn, *args) -> Future:
        return self._pool.submit(fn, self.key, self.mech, *args)

    def _submit(self, chunks: list[np.ndarray]) -> list[Future]:
        """Futures of the chunks; a pool already broken (a worker died while idle)
        is replaced first."""
        try:
            return [self._task(_evaluate_chunk, chunk) for chunk in chunks]
        except BrokenProcessPool:
            self._pool.shutdown(wait=False, cancel_futures=True)
            self.restarts += 1
            self._pool = self._start_pool()
            return [self._task(_evaluate_chunk, chunk) for chunk in chunks]

    def _compile_ahead(self, chunks: list[np.ndarray]) -> None:
        """On a cold start (the evaluation of a chunk never traced on this machine),
        the first worker compiles the partial gradients of the chunks before its first
        chunk, while this process compiles the evaluation: the two largest programs
        compile side by side on two cores instead of the evaluation twice (module
        docstring). Asked once, at the first batch."""
        if self._pool is None or self._cold_checked:
            return
        self._cold_checked = True
        if batch_traced_before(self.mech, len(chunks[0])):
            return
        sizes = tuple(dict.fromkeys(len(chunk) for chunk in chunks))
        try:
            self._compiling = self._task(_compile_gradients, sizes)
        except BrokenProcessPool:  # _submit replaces the pool
            pass

    def _await_compiled(self) -> None:
        """Wait for :meth:`_compile_ahead`'s compilation, whose executables this
        process then loads from the persistent cache; if it failed (a worker died),
        this process compiles them itself."""
        compiling, self._compiling = self._compiling, None
        if compiling is not None:
            try:
                compiling.result()
            except Exception:
                pass

    def _collect(self, futures: list[Future], chunks: list[np.ndarray]) -> list:
        """The workers' results in chunk order. A worker that died (killed, or its
        process crashed) breaks the pool: a new pool recomputes the chunks that had no
        result, ``RETRIES`` times, then this process computes them itself. Each chunk's
        numbers do not depend on the process, so the run stays bit-identical."""
        results: list = [None] * len(chunks)
        todo = list(range(len(chunks)))
        for attempt in range(RETRIES + 1):
            for i in list(todo):
                try:
                    results[i] = futures[i].result()
                    todo.remove(i)
                except BrokenProcessPool:
                    pass
            if not todo:
                return results
            self._pool.shutdown(wait=False, cancel_futures=True)
            self.restarts += 1
            self._pool = self._start_pool()
            if attempt < RETRIES:
                resubmitted = self._submit([chunks[i] for i in todo])
                for i, future in zip(todo, resubmitted):
                    futures[i] = future
        for i in todo:
            results[i] = _evaluate_chunk_here(self.mech, chunks[i])
        return results

    def _chunks(self, n: int) -> list[slice]:
        return chunk_slices(n, self.count)

    def evaluate(self, designs: Float[Array, "N n_p"]) -> Evaluation:
        """:func:`linkopt._design.evaluation.evaluate` of a batch of designs, as numpy
        arrays."""
        designs = np.asarray(designs, dtype=float)
        chunks = [designs[c] for c in self._chunks(len(designs))]
        if len(chunks) > 1:
            self._compile_ahead(chunks)
        pending = (
            self._submit(chunks[1:])
            if self._pool is not None and len(chunks) > 1
            else None
        )
        with one_blas_thread():
            first = jax.tree_util.tree_map(np.asarray, evaluate(self.mech, chunks[0]))
            self.first = (chunks[0][0], jax.tree_util.tree_map(lambda a: a[0], first))
            if pending is not None and not all(f.done() for f in pending):
                # idle until they answer
                alpha = alpha_minus(self.mech)
                self._early = (
                    chunks[0],
                    first,
                    alpha,
                    self._gradient(chunks[0], first, alpha),
                )
        rest = self._collect(pending, chunks[1:]) if pending is not None else []
        return concatenate([first] + rest)

    def _gradient(
        self, designs: np.ndarray, evaluation: Evaluation, alpha: float
    ) -> np.ndarray:
        early = self._early
        if (
            early is not None
            and early[2] == alpha
            and np.array_equal(early[0], designs)
            and all(
                a is b is None or np.array_equal(a, b, equal_nan=True)
                for a, b in (
                    (getattr(early[1], f.name), getattr(evaluation, f.name))
                    for f in dataclasses.fields(evaluation)
                )
            )
        ):
            return early[3]
        self._await_compiled()
        return np.asarray(partial_gradient(self.mech, designs, evaluation, alpha))

    def partial_gradient(
        self, designs: Float[Array, "N n_p"], evaluation: Evaluation, alpha: float
    ) -> np.ndarray:
        """:func:`linkopt._design.partial.partial_gradient` of a batch, shape
        ``(N, n_p)``, chunk by chunk in this process (module docstring)."""
        designs = np.asarray(designs, dtype=float)
        with one_blas_thread():
            return np.concatenate(
                [
                    self._gradient(
                        designs[c],
                        jax.tree_util.tree_map(lambda a, c=c: a[c], evaluation),
                        alpha,
                    )
                    for c in self._chunks(len(designs))
                ]
            )

    def close(self) -> None:
        """End the processes, or hand them to :func:`linkopt._design.ahead.keep`
        where the command line asked for that (the run's final outputs use one)."""
        if self._pool is not None:
            if not ahead.keep(self.count, self._pool):
                self._pool.shutdown(wait=True)
            self._pool = None

    def __enter__(self) -> Workers:
        return self

    def __exit__(self, *exc) -> None:
        if self._pool is not None and exc[0] is not None:
            self._pool.shutdown(wait=False, cancel_futures=True)
            self._pool = None
        self.close()
