"""The one loop that runs every solver of :mod:`linkopt._engine.solvers`."""

from __future__ import annotations

import enum
from typing import Any, Protocol

import jax
import jax.numpy as jnp
from jaxtyping import Array, Bool, Int

from ... import _config  # noqa: F401  (float64 on before any array)


class Result(enum.IntEnum):
    """Why a solve stopped, as an integer array inside traced code."""

    SUCCESSFUL = 0
    MAX_ITERATIONS = 1  # the iteration cap, before the solver's own test
    STALLED = 2  # no acceptable step is left (damping or step size at its limit)


class Solver(Protocol):
    def init(self, y0) -> Any: ...

    def step(self, state) -> Any: ...

    def terminate(self, state) -> tuple[Bool[Array, ""], Int[Array, ""]]: ...


def stopped(solver: Solver, state, max_iterations) -> Bool[Array, ""]:
    """Whether ``state`` ends its solve: terminated, or at the iteration cap."""
    done, _ = solver.terminate(state)
    return done | (state.iteration >= max_iterations)


def run(solver: Solver, y0, max_iterations) -> tuple[Any, Int[Array, ""]]:
    """``solver`` from ``y0`` until it terminates or ``state.iteration`` reaches
    ``max_iterations``: ``(final state, Result code)``."""
    state = jax.lax.while_loop(
        lambda st: ~stopped(solver, st, max_iterations), solver.step, solver.init(y0)
    )
    done, result = solver.terminate(state)
    return state, jnp.where(done, result, Result.MAX_ITERATIONS)
