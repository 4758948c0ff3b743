"""Batched calls in blocks of a fixed number of rows, so one compiled program serves
every batch size.

A jitted function is traced and compiled once per argument shape, and for linkopt's
solves a compilation costs seconds where running a block costs milliseconds
(``benchmarks/bench_compile.py`` lists a command's compilations). Maps, verification
and animations ask for many batch sizes (each continuation wave has its own: about four
for a 60² map, three more for a 41² verification, one for each σ_min and read-out
batch), so with a program per batch size a first run would spend most of its time
compiling. :func:`in_blocks` calls the function on consecutive blocks of exactly
:data:`BLOCK` rows instead (the last block padded by repeating its last row, whose
results are dropped): whatever the batch size, one program. The cost is the padding (at
most ``BLOCK - 1`` rows a call) and one dispatch per block (about 0.1 ms).

Blocks are independent, so a batch of several blocks runs them on up to
:data:`THREADS` threads of the calling process (XLA runs each program without holding
Python's lock, so the threads keep that many cores busy): a user's large batch of
solves uses every core of one process, with the same numbers as one block after
another.

Only concrete arrays are blocked: under ``jax.jit``, ``vmap`` or ``grad`` (a tracer
among the arguments) the function is called once on the whole batch, so solves stay
differentiable.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from concurrent.futures import ThreadPoolExecutor

import jax
import numpy as np

from .. import _config  # noqa: F401  (float64 on before any array)
from .._machine import cores

#: Rows per block. 64 is two of the solver's 32-lane chunks (``kinematics.CHUNK``): a
#: 2-D map's wave (at most about twice its side) takes one or two blocks.
BLOCK = 64


#: Most threads that run one batch's blocks at once: the cores this process may use.
THREADS = cores()
#: The shortest padded continuation path (:func:`path_rows`).
PATH_BLOCK = 16


def _padded(a: np.ndarray, rows: int) -> np.ndarray:
    """``a`` with its last row repeated up to ``rows`` rows."""
    return np.concatenate([a, np.repeat(a[-1:], rows - len(a), axis=0)])


def in_blocks(
    fn: Callable,
    rows: Sequence[np.ndarray],
    width: int = BLOCK,
    one: Callable | None = None,
) -> object:
    """``fn(*rows)`` computed on blocks of exactly ``width`` rows of ``rows`` (arrays
    sharing their leading axis ``N``); the results (a pytree of arrays with leading
    axis ``width``) are concatenated and cut back to ``N`` rows.

    ``one`` (optional) computes the same for one row without its batch axis: a batch
    of one row then runs that program (the one a single solve uses) instead of a block
    padded with ``width - 1`` copies, which costs many single solves
    (``benchmarks/bench_kinematics.py`` times a batch of one)."""
    rows = [np.asarray(r) for r in rows]
    count = len(rows[0])
    if count == 0:
        return fn(*rows)
    if count == 1 and one is not None:
        single = one(*(r[0] for r in rows))
        return jax.tree_util.tree_map(
            lambda leaf: _joined([np.asarray(leaf)[None]], 1), single
        )
    total = -(-count // width) * width
    padded = [_padded(r, total) for r in rows]
    starts = range(0, total, width)
    threads = min(THREADS, len(starts))
    if threads == 1:  # dispatched one after another, joined once all are queued
        parts = [fn(*(r[start : start + width] for r in padded)) for start in starts]
    else:

        def block(start: int):
            return _fetched(fn(*(r[start : start + width] for r in padded)))

        # the first block dispatched alone: a program new to this process compiles
        # once, before any other thread calls it; it then runs while the others are
        # dispatched (a thread waits for it), so at most ``threads`` blocks run at once
        first = fn(*(r[:width] for r in padded))
        with ThreadPoolExecutor(threads) as pool:
            waited = pool.submit(_fetched, first)
            rest = list(pool.map(block, starts[1:]))
            parts = [waited.result(), *rest]
    return jax.tree_util.tree_map(lambda *leaves: _joined(leaves, count), *parts)


def _fetched(tree):
    """Every array of ``tree`` as numpy: waits for a dispatched program (Python's lock
    released)."""
    return jax.tree_util.tree_map(np.asarray, tree)


def _joined(leaves, count: int) -> jax.Array:
    """The blocks' results joined and cut to ``count`` rows in numpy, then put back on
    the device: a jax slice (and ``jnp.asarray``) compiles a small program for each
    new ``count``, a few hundred of them in a first run."""
    return jax.device_put(np.concatenate([np.asarray(leaf) for leaf in leaves])[:count])


def first_rows(tree, count: int):
    """Every array of ``tree`` cut to its first ``count`` rows (:func:`_joined`)."""
    return jax.tree_util.tree_map(lambda leaf: _joined([leaf], count), tree)


def path_rows(count: int) -> int:
    """The rows a continuation path of ``count`` rows is padded to: the next power of
    two from :data:`PATH_BLOCK` on (few lengths, so few programs; a padded row repeats
    the last one, a continuation of length zero that costs one residual check)."""
    size = PATH_BLOCK
    while size < count:
        size *= 2
    return size
