"""Chord (simplified-Newton) steps: ``x ← x - step(C(x))`` with one fixed linear map
``step`` (a factor computed once), for the continuation's corrector
(:func:`linkopt._engine.banded.predict`): one residual and two triangular solves
a step, where a Levenberg–Marquardt iteration builds the rows' Jacobian, assembles
``JᵀJ`` and factors it.

From the first-order prediction of a continuation step the chord converges linearly,
its rate proportional to the step (the fixed Jacobian is the one of the state the
step started from); a LM iteration converges quadratically but costs several chord
steps. So the loop stops where the chord stops paying: at the tolerance, after
:data:`LIMIT` steps, or at the first step that shrinks ``max |C|`` by less than
:data:`CONTRACTION` (that step is kept only if it lowered ``max |C|``). A
``while_loop`` rather than unrolled steps: the program does not grow with the limit.

Measured (``benchmarks/bench_bodies.py``'s linkages, SPAN 0.05 rad, banded, CPU per
solve against the walk without chord steps in one process, load 6-7): unrolled fixed
counts helped more the more steps they took (ladder of 300 bodies: 1, 2, 3 steps left
5.9, 1.4, 0.9 LM iterations of 6.1; 6 steps none) and grew the compile with the
count; this loop (limit 8, contraction 0.25 or 0.5, alike) took that ladder from 27.9
to 7.1-7.4 ms and lazy tongs of 100 bodies from 5.3 to 1.3 ms, no LM iteration left.
The from-rest program of a 100-body ladder grows from 3595 to 4148 jaxpr equations
(compile CPU 6.9 -> 8.8 s, loaded).
"""

from __future__ import annotations

from collections.abc import Callable

import jax
import jax.numpy as jnp

from ... import _config  # noqa: F401  (float64 on before any array)

#: Most chord steps per continuation step.
LIMIT = 8
#: A chord step must shrink ``max |C|`` at least this much for the next one to run.
CONTRACTION = 0.25


def _size(residual) -> jax.Array:
    return jnp.max(jnp.stack([jnp.max(jnp.abs(r)) for r in jax.tree.leaves(residual)]))


def solve(
    residual: Callable, step: Callable, x0, *, tolerance: float, limit: int = LIMIT
):
    """``x`` after the chord steps ``x ← x - step(residual(x))`` from ``x0`` (module
    docstring); ``residual`` returns any pytree of arrays, ``step`` maps it to a
    change of ``x``; at most ``limit`` steps."""
    r0 = residual(x0)

    def cond(carry):
        _, _, size, k, going = carry
        return going & (k < limit) & (size > tolerance)

    def body(carry):
        x, r, size, k, _ = carry
        trial = x - step(r)
        r_trial = residual(trial)
        size_trial = _size(r_trial)
        better = size_trial < size  # False for NaN
        keep = lambda new, old: jnp.where(better, new, old)  # noqa: E731
        return (
            keep(trial, x),
            jax.tree.map(keep, r_trial, r),
            jnp.where(better, size_trial, size),
            k + 1,
            size_trial <= CONTRACTION * size,
        )

    start = (x0, r0, _size(r0), jnp.asarray(0), jnp.asarray(True))
    return jax.lax.while_loop(cond, body, start)[0]
