"""The swarm's particles split over worker processes.

XLA's CPU pool runs with one thread here (see :mod:`linkopt._config`), so one process
keeps one core busy. :class:`Workers` spawns ``count`` processes that each hold the
mechanism and evaluate (and differentiate) a contiguous chunk of the particles; the
chunks' results are concatenated in particle order. Each chunk is the same batched,
jitted call as in a single process, so the persistent compilation cache serves every
worker after the first run. A chunk's numbers do not depend on which process computed
it, so a run with the same seed and worker count always gives the same result.
With ``count = 1`` everything runs in the calling process.
"""

from __future__ import annotations

import multiprocessing

import jax
import numpy as np
from jaxtyping import Array, Float

from ._evaluation import Evaluation, evaluate
from ._model import Mechanism
from ._partial import partial_gradient

_MECHANISM: Mechanism | None = None  # set in each worker process by _initialise


def _initialise(mech: Mechanism) -> None:
    global _MECHANISM
    _MECHANISM = mech


def _evaluate_chunk(designs: np.ndarray) -> Evaluation:
    return jax.tree_util.tree_map(np.asarray, evaluate(_MECHANISM, designs))


def _gradient_chunk(job: tuple[np.ndarray, Evaluation, float]) -> np.ndarray:
    designs, evaluation, alpha = job
    return np.asarray(partial_gradient(_MECHANISM, designs, evaluation, alpha))


def _concatenate(parts: list[Evaluation]) -> Evaluation:
    return Evaluation(*(np.concatenate(fields) for fields in zip(*parts)))


class Workers:
    """``count`` processes sharing the particles of every batched call."""

    def __init__(self, mech: Mechanism, count: int = 1):
        if count < 1:
            raise ValueError(f"count must be a positive number of processes, got {count}")
        self.mech = mech
        self.count = count
        self._pool = None
        if count > 1:
            context = multiprocessing.get_context("spawn")  # fork would copy JAX's threads
            self._pool = context.Pool(count, initializer=_initialise, initargs=(mech,))

    def _chunks(self, n: int) -> list[slice]:
        bounds = np.linspace(0, n, min(self.count, n) + 1).round().astype(int)
        return [slice(a, b) for a, b in zip(bounds[:-1], bounds[1:])]

    def evaluate(self, designs: Float[Array, "N n_p"]) -> Evaluation:
        """:func:`linkopt._evaluation.evaluate` of a batch of designs, as numpy arrays."""
        designs = np.asarray(designs, dtype=float)
        if self._pool is None:
            return jax.tree_util.tree_map(np.asarray, evaluate(self.mech, designs))
        return _concatenate(self._pool.map(_evaluate_chunk, [designs[c] for c in self._chunks(len(designs))]))

    def partial_gradient(self, designs: Float[Array, "N n_p"], evaluation: Evaluation, alpha: float) -> np.ndarray:
        """:func:`linkopt._partial.partial_gradient` of a batch, shape ``(N, n_p)``."""
        designs = np.asarray(designs, dtype=float)
        if self._pool is None:
            return np.asarray(partial_gradient(self.mech, designs, evaluation, alpha))
        jobs = [(designs[c], jax.tree_util.tree_map(lambda a, c=c: a[c], evaluation), alpha) for c in self._chunks(len(designs))]
        return np.concatenate(self._pool.map(_gradient_chunk, jobs))

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
