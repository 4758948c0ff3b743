"""The swarm's particles split over worker processes.

XLA's CPU pool runs with one thread here (see :mod:`linkopt._config`), so one process
keeps one core busy. :class:`Workers` splits the particles into ``count`` contiguous
chunks: the calling process evaluates (and differentiates) the first itself while
``count - 1`` spawned processes, each holding the mechanism, take the others; the
chunks' results are concatenated in particle order. The caller works rather than waits
because a spawned process costs a Python and JAX start-up (about 1 s) before its
first evaluation, and the caller has paid that already (five-bar, 2 processes, warm
cache: 14.4 s in the optimiser instead of 15.3 s). Each chunk is the same batched,
jitted call as in a single process, so the persistent compilation cache serves every
worker after the first run. A chunk's numbers do not depend on which process computed
it, so a run with the same seed and worker count always gives the same result.
With ``count = 1`` everything runs in the calling process.

jaxlib's LAPACK kernels call the OpenBLAS that scipy ships, which starts one thread per
core and keeps it spinning between calls. Two processes, each with that thread beside
its own, put four busy threads on two cores: the 10-design five-bar chunks then took
2.6-3.7 s per iteration instead of 1.0-1.1 s. Every chunk therefore runs with OpenBLAS held to one thread
(``threadpoolctl``): in the workers for their lifetime, in the calling process only
while it computes its chunk, so the user's own numpy keeps its threads. One process
alone gains too (20 designs: 1.9 s instead of 2.0-2.3 s).
"""

from __future__ import annotations

import multiprocessing

import jax
import numpy as np
from jaxtyping import Array, Float
from threadpoolctl import threadpool_limits

from ._evaluation import Evaluation, evaluate
from ._model import Mechanism
from ._partial import partial_gradient

_MECHANISM: Mechanism | None = None  # set in each worker process by _initialise


def _initialise(mech: Mechanism) -> None:
    global _MECHANISM
    _MECHANISM = mech
    threadpool_limits(1, user_api="blas")  # for the worker's lifetime (module docstring)


def _evaluate_chunk(designs: np.ndarray) -> Evaluation:
    return jax.tree_util.tree_map(np.asarray, evaluate(_MECHANISM, designs))


def _gradient_chunk(job: tuple[np.ndarray, Evaluation, float]) -> np.ndarray:
    designs, evaluation, alpha = job
    return np.asarray(partial_gradient(_MECHANISM, designs, evaluation, alpha))


def _concatenate(parts: list[Evaluation]) -> Evaluation:
    return Evaluation(*(np.concatenate(fields) for fields in zip(*parts)))


class Workers:
    """``count`` processes (this one and ``count - 1`` spawned) sharing the particles of
    every batched call."""

    def __init__(self, mech: Mechanism, count: int = 1):
        if count < 1:
            raise ValueError(f"count must be a positive number of processes, got {count}")
        self.mech = mech
        self.count = count
        self._pool = None
        if count > 1:
            context = multiprocessing.get_context("spawn")  # fork would copy JAX's threads
            self._pool = context.Pool(count - 1, initializer=_initialise, initargs=(mech,))

    def _chunks(self, n: int) -> list[slice]:
        bounds = np.linspace(0, n, min(self.count, n) + 1).round().astype(int)
        return [slice(a, b) for a, b in zip(bounds[:-1], bounds[1:])]

    def _map(self, local, remote, jobs: list) -> list:
        """``[local(jobs[0]), remote(jobs[1]), ...]``, the remote ones in the pool meanwhile."""
        pending = self._pool.map_async(remote, jobs[1:]) if self._pool is not None and len(jobs) > 1 else None
        with threadpool_limits(1, user_api="blas"):
            first = local(jobs[0])
        return [first] + (pending.get() if pending is not None else [])

    def evaluate(self, designs: Float[Array, "N n_p"]) -> Evaluation:
        """:func:`linkopt._evaluation.evaluate` of a batch of designs, as numpy arrays."""
        designs = np.asarray(designs, dtype=float)
        local = lambda chunk: jax.tree_util.tree_map(np.asarray, evaluate(self.mech, chunk))  # noqa: E731
        return _concatenate(self._map(local, _evaluate_chunk, [designs[c] for c in self._chunks(len(designs))]))

    def partial_gradient(self, designs: Float[Array, "N n_p"], evaluation: Evaluation, alpha: float) -> np.ndarray:
        """:func:`linkopt._partial.partial_gradient` of a batch, shape ``(N, n_p)``."""
        designs = np.asarray(designs, dtype=float)
        jobs = [(designs[c], jax.tree_util.tree_map(lambda a, c=c: a[c], evaluation), alpha) for c in self._chunks(len(designs))]
        local = lambda job: np.asarray(partial_gradient(self.mech, *job))  # noqa: E731
        return np.concatenate(self._map(local, _gradient_chunk, jobs))

    def close(self) -> None:
        if self._pool is not None:
            self._pool.close()
            self._pool.join()
            self._pool = None

    def __enter__(self) -> Workers:
        return self

    def __exit__(self, *exc) -> None:
        if self._pool is not None and exc[0] is not None:
            self._pool.terminate()
        self.close()
