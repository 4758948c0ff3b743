"""Levenberg–Marquardt for small dense nonlinear least squares, ``min_s ½|C(s)|²``.

Hand-written rather than ``optimistix.LevenbergMarquardt`` because the constraint solves
are tiny (35-70 unknowns) and warm-started: a solve takes 3-4 iterations and the
per-iteration overhead dominates. optimistix fixes its initial damping at 1, which
costs several extra iterations from a warm start; ``benchmarks/bench_kinematics.py``
keeps it as the comparison.

Shape follows optimistix: :func:`init`, :func:`step`, :func:`terminate`, run by
:func:`solve` in a ``lax.while_loop``. The step solves ``(JᵀJ + λI) δ = -Jᵀr`` by
Cholesky (:mod:`linkopt._engine.dense`, no LAPACK call; ``J`` may be tall with redundant
rows, e.g. a planar loop written in 3-D); damping follows Nielsen's rule: on acceptance
``λ *= max(1/3, 1 - (2ρ - 1)³)``, on rejection ``λ *= ν, ν *= 2``. Failure is a value: a
stall at a non-zero local minimum (damping beyond ``1e12`` or a step below ``1e-15``) or
the iteration cap ends the loop with ``converged = False``.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import NamedTuple

import jax
import jax.numpy as jnp
from jaxtyping import Array, Bool, Float, Int

from . import dense

Residual = Callable[[Float[Array, " n"]], Float[Array, " m"]]
#: ``x -> (C(x), J(x)ᵀJ(x), J(x)ᵀC(x))``: the residual and its Gauss–Newton normal
#: equations.
Linearisation = Callable[
    [Float[Array, " n"]],
    tuple[Float[Array, " m"], Float[Array, "n n"], Float[Array, " n"]],
]

MAX_DAMPING = 1e12
MIN_STEP = 1e-15


class LMState(NamedTuple):
    x: Float[Array, " n"]
    residual: Float[Array, " m"]
    hessian: Float[Array, "n n"]  # JᵀJ at x (Gauss–Newton)
    gradient: Float[Array, " n"]  # Jᵀr at x
    damping: Float[Array, ""]
    growth: Float[Array, ""]
    iteration: Int[Array, ""]
    stalled: Bool[Array, ""]


class LMResult(NamedTuple):
    """Outcome of a solve: ``converged`` iff ``max |C| <= tolerance``."""

    x: Float[Array, " n"]
    converged: Bool[Array, ""]
    residual: Float[Array, ""]  # max |C| at x
    iterations: Int[Array, ""]


def _jacfwd_linearisation(fn: Residual, x):
    jacobian, residual = jax.jacfwd(lambda y: (fn(y), fn(y)), has_aux=True)(x)
    return residual, jacobian.T @ jacobian, jacobian.T @ residual


def _linearise(fn: Residual, x, linearise: Linearisation | None = None):
    """``(C(x), JᵀJ, JᵀC)``: from ``linearise`` if given, else by ``jax.jacfwd`` of
    ``fn``."""
    if linearise is not None:
        return linearise(x)
    return _jacfwd_linearisation(fn, x)


def init(
    fn: Residual, x0, initial_damping: float, linearise: Linearisation | None = None
) -> LMState:
    residual, hessian, gradient = _linearise(fn, x0, linearise)
    return LMState(
        x0,
        residual,
        hessian,
        gradient,
        jnp.asarray(initial_damping),
        jnp.asarray(2.0),
        jnp.asarray(0),
        jnp.asarray(False),
    )


def step(
    fn: Residual, state: LMState, linearise: Linearisation | None = None
) -> LMState:
    """One damped Gauss–Newton step with Nielsen's damping update."""
    hessian, gradient, r, lam = (
        state.hessian,
        state.gradient,
        state.residual,
        state.damping,
    )
    delta = -dense.damped_solve(hessian, lam, gradient)  # (JᵀJ + λI)⁻¹ Jᵀr
    new_residual, new_hessian, new_gradient = _linearise(fn, state.x + delta, linearise)
    actual = r @ r - new_residual @ new_residual
    predicted = -(2.0 * delta @ gradient + delta @ hessian @ delta)
    rho = actual / jnp.where(predicted > 0, predicted, 1.0)
    accept = (actual > 0) & (predicted > 0) & jnp.all(jnp.isfinite(new_residual))
    shrink = jnp.maximum(1.0 / 3.0, 1.0 - (2.0 * rho - 1.0) ** 3)
    tiny = jnp.sqrt(delta @ delta) < MIN_STEP * (1.0 + jnp.sqrt(state.x @ state.x))
    return LMState(
        x=jnp.where(accept, state.x + delta, state.x),
        residual=jnp.where(accept, new_residual, r),
        hessian=jnp.where(accept, new_hessian, hessian),
        gradient=jnp.where(accept, new_gradient, gradient),
        damping=jnp.where(accept, lam * shrink, lam * state.growth),
        growth=jnp.where(accept, 2.0, 2.0 * state.growth),
        iteration=state.iteration + 1,
        stalled=(~accept & (lam * state.growth > MAX_DAMPING)) | (tiny & ~accept),
    )


def terminate(state: LMState, tolerance: float, max_iterations: int) -> Bool[Array, ""]:
    done = jnp.max(jnp.abs(state.residual)) <= tolerance
    return done | state.stalled | (state.iteration >= max_iterations)


def solve(
    fn: Residual,
    x0,
    *,
    tolerance: float,
    max_iterations: int,
    initial_damping: float,
    linearise: Linearisation | None = None,
) -> LMResult:
    """Minimise ``½|fn(x)|²`` from ``x0``; jit- and vmap-friendly, no NaN on failure.

    ``linearise`` (optional) gives ``(fn(x), JᵀJ, Jᵀfn(x))`` directly (the constraint
    solves pass :func:`linkopt._engine.jacobian.normal_equations`); without it
    ``jax.jacfwd``.
    """
    state = init(fn, x0, initial_damping, linearise)
    state = jax.lax.while_loop(
        lambda st: ~terminate(st, tolerance, max_iterations),
        lambda st: step(fn, st, linearise),
        state,
    )
    error = jnp.max(jnp.abs(state.residual))
    converged = error <= tolerance
    return LMResult(
        state.x,
        converged,
        jnp.where(jnp.isfinite(error), error, jnp.inf),
        state.iteration,
    )
