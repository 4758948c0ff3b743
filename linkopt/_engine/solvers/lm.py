"""Levenberg–Marquardt for small dense nonlinear least squares, ``min_x ½|C(x)|²``: the
package's one LM loop, with two steps.

Hand-written rather than ``optimistix.LevenbergMarquardt`` because the constraint solves
are tiny (35-70 unknowns) and warm-started: a solve takes 3-4 iterations and the
per-iteration overhead dominates. optimistix fixes its initial damping at 1, which
costs several extra iterations from a warm start; ``benchmarks/bench_kinematics.py``
keeps it as the comparison. Neither step below is one of optimistix's.

:class:`LevenbergMarquardt` is a solver of the package's protocol (``init``, ``step``,
``terminate``, run by :func:`linkopt._engine.solvers.driver.run`; :func:`solve` wraps
it). What differs between problems is the *method* (a frozen dataclass, static to the
loop): how it linearises ``C`` at ``x`` and which damped step it takes from that
linearisation.

* :class:`NormalEquations` (the FK/BK constraint solves, square or tall ``J`` with
  redundant rows, e.g. a planar loop written in 3-D): ``(JᵀJ + λI) δ = -Jᵀr`` by
  Cholesky (:mod:`linkopt._engine.dense`, no LAPACK call).
* :class:`MinimumNorm` (the assembly, :mod:`linkopt._files.assembly.solve`, more
  unknowns than rows, ``JᵀJ`` singular up to λ; also the linearisation of
  :mod:`~linkopt._engine.solvers.projection`): the least weighted-norm step
  ``δ = -S Jₛᵀ (Jₛ Jₛᵀ + λI)⁻¹ r`` with ``Jₛ = J S``, ``S = diag(scale)``.

A method may also bend its step along the residual's curvature at ``x``
(:class:`linkopt._engine.banded.Banded`'s geodesic acceleration).

Shared by all: a step is taken iff it lowers ``|C|²`` and its linear model predicted
a decrease; damping follows Nielsen's rule: on acceptance
``λ *= max(1/3, 1 - (2ρ - 1)³)``, on rejection ``λ *= ν, ν *= 2``.

A solver made with ``residual_scaled`` keeps the damping proportional to the squared
residual, ``λ = μ |C|²``, and Nielsen's rule updates the multiplier ``μ`` instead: on
acceptance ``λ`` also falls with ``|C|²`` (``λ *= max(1/3, …) · |C_new|² / |C|²``, not
below :data:`MIN_DAMPING`), on rejection it grows as before. That is the damping of
Yamashita & Fukushima (2001) and Fan & Yuan (2005), whose local convergence is
quadratic without a nonsingular ``JᵀJ``, with the multiplier adapted by the gain
ratio as in Fan (2012). Why: where the linear model is exact (``ρ ≈ 1``) Nielsen's
rule lowers ``λ`` only threefold an iteration, so a mode whose eigenvalue of ``JᵀJ``
lies far below the initial damping (the long, soft linkages of
:mod:`linkopt._engine.banded`, which take it) converges only once ``λ`` has come down
to it. Measured on lazy tongs of 1000 bodies (smallest eigenvalue 3.2e-12), one
continuation step from rest with geodesic acceleration: 16 iterations to
``max |C| <= 1e-12`` with Nielsen's rule, 3 with this one (0.04 rad; 18 and 7 for a
0.25 rad step); capping ``λ`` at ``|C|²`` alone took 3 and 16 (after each accepted
step the damping fell too far, and three rejections raised it again).

Failure is a value:
a stall at a non-zero local minimum (damping beyond ``1e12`` or a step below
``1e-15``) or the iteration cap ends the loop with ``converged = False``.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Protocol

import jax
import jax.numpy as jnp
from jaxtyping import Array, Bool, Float, Int

from .. import dense, dense_lu
from .driver import Result, run

Residual = Callable[[Float[Array, " n"]], Float[Array, " m"]]
#: ``x -> (C(x), J(x)ᵀJ(x), J(x)ᵀC(x))``: the residual and its Gauss–Newton normal
#: equations.
Linearisation = Callable[
    [Float[Array, " n"]],
    tuple[Float[Array, " m"], Float[Array, "n n"], Float[Array, " n"]],
]

MAX_DAMPING = 1e12
MIN_STEP = 1e-15
#: Least damping the ``residual_scaled`` rule sets, below the rounding of a ``JᵀJ``
#: whose entries are of order one (so no step changes by it): without it the damping
#: would follow ``|C|²`` to 1e-30 and below, and a rejected step near a singular
#: ``JᵀJ`` would take that many more doublings to raise it again.
MIN_DAMPING = 1e-15


@jax.tree_util.register_dataclass
@dataclass(frozen=True)
class LMState:
    """The loop's carry. ``model`` is what the method's step needs of the linearisation
    at ``x`` (``(JᵀJ, Jᵀr)`` or ``J S``), kept so that a rejected step costs no new
    linearisation."""

    x: Float[Array, " n"]
    residual: Float[Array, " m"]
    model: Any
    damping: Float[Array, ""]
    growth: Float[Array, ""]
    iteration: Int[Array, ""]
    stalled: Bool[Array, ""]


@jax.tree_util.register_dataclass
@dataclass(frozen=True)
class LMResult:
    """Outcome of a solve: ``converged`` iff ``max |C| <= tolerance``."""

    x: Float[Array, " n"]
    converged: Bool[Array, ""]
    residual: Float[Array, ""]  # max |C| at x
    iterations: Int[Array, ""]
    #: ``(C(x), model)``: the method's linearisation at ``x``, for a caller that goes
    #: on from ``x`` (:func:`linkopt._engine.continuation.walk`'s next
    #: prediction); unused, it costs nothing (the loop carries it anyway)
    linearisation: Any = None


class Method(Protocol):
    def linearise(self, x) -> tuple[Float[Array, " m"], Any]:
        """``(C(x), model)``."""

    def direction(self, x, model, residual, damping) -> tuple[Float[Array, " n"], Any]:
        """The damped step ``δ`` from ``x`` and the decrease of ``|C|²`` its linear
        model predicts."""


@dataclass(frozen=True)
class NormalEquations:
    """``δ = -(JᵀJ + λI)⁻¹ Jᵀr`` by Cholesky. ``linearisation`` (optional) gives
    ``(fn(x), JᵀJ, Jᵀfn(x), *extra)`` directly (the constraint solves pass
    :func:`linkopt._engine.jacobian.normal_equations`); without it ``jax.jacfwd``.
    The model is ``(JᵀJ, Jᵀr, *extra)``: anything else the linearisation gives rides
    along to the result's ``linearisation``."""

    fn: Residual
    linearisation: Linearisation | None = None

    def linearise(self, x):
        if self.linearisation is not None:
            residual, hessian, gradient, *extra = self.linearisation(x)
        else:
            jacobian, residual = value_and_jacobian(self.fn, x)
            hessian, gradient, extra = jacobian.T @ jacobian, jacobian.T @ residual, ()
        return residual, (hessian, gradient, *extra)

    def direction(self, x, model, residual, damping):
        return normal_step(*model[:2], damping)


def normal_step(hessian, gradient, damping) -> tuple[Float[Array, " n"], Any]:
    """:class:`NormalEquations`' damped step ``δ = -(JᵀJ + λI)⁻¹ Jᵀr`` and the
    decrease of ``|C|²`` its linear model predicts."""
    delta = -dense.damped_solve(hessian, damping, gradient)
    return delta, -(2.0 * delta @ gradient + delta @ hessian @ delta)


@dataclass(frozen=True)
class MinimumNorm:
    """``δ = -S Jₛᵀ (Jₛ Jₛᵀ + λI)⁻¹ r``, ``Jₛ = J S``: of the damped least-squares
    steps, the one of least length in the variables ``y = S⁻¹x`` (``scale`` 0 holds a
    variable). λ enters the solve no lower than ``floor``, so redundant rows
    (``Jₛ Jₛᵀ`` singular) never meet an exactly singular system."""

    fn: Residual
    scale: Float[Array, " n"]
    floor: float = 1e-15

    def linearise(self, x):
        jacobian, residual = value_and_jacobian(self.fn, x)
        return residual, jacobian * self.scale[None, :]

    def direction(self, x, model, residual, damping):
        gram, u = gram_solve(model, jnp.maximum(damping, self.floor), residual)
        after = residual - gram @ u  # C + J δ, the linear model after the step
        return -self.scale * (model.T @ u), residual @ residual - after @ after


def value_and_jacobian(fn: Residual, x) -> tuple[Float[Array, "m n"], Any]:
    """``(∂fn/∂x, fn(x))`` by forward mode, ``fn`` traced once (its value is the
    primal of the same pushforward)."""

    def both(y):
        value = fn(y)
        return value, value

    return jax.jacfwd(both, has_aux=True)(x)


def gram_solve(jacobian, damping, rhs):
    """``(J Jᵀ, (J Jᵀ + μI)⁻¹ rhs)`` by LU: ``Jᵀ`` times the second is the least-norm
    ``d`` of ``J d = rhs`` (damped by ``μ``)."""
    gram = jacobian @ jacobian.T
    eye = jnp.eye(gram.shape[0])
    return gram, dense_lu.solve(gram + damping * eye, rhs)


@dataclass(frozen=True)
class LevenbergMarquardt:
    """Minimise ``½|C(x)|²`` by ``method``'s damped steps until ``max |C| <=
    tolerance`` or a stall (module docstring)."""

    method: Method
    tolerance: float
    initial_damping: float
    #: damping proportional to ``|C|²`` (module docstring)
    residual_scaled: bool = False

    def init(self, x0) -> LMState:
        residual, model = self.method.linearise(x0)
        return initial_state(x0, residual, model, self.initial_damping)

    def step(self, state: LMState) -> LMState:
        """One damped step with Nielsen's damping update."""
        delta, predicted = self.method.direction(
            state.x, state.model, state.residual, state.damping
        )
        trial = state.x + delta
        return update(
            state,
            trial,
            delta,
            predicted,
            *self.method.linearise(trial),
            residual_scaled=self.residual_scaled,
        )

    def terminate(self, state: LMState):
        converged = jnp.max(jnp.abs(state.residual)) <= self.tolerance
        result = jnp.where(converged, Result.SUCCESSFUL, Result.STALLED)
        return converged | state.stalled, result


def initial_state(x0, residual, model, initial_damping) -> LMState:
    """The loop's carry at ``x0``, linearised there as ``(residual, model)``."""
    return LMState(
        x0,
        residual,
        model,
        jnp.asarray(initial_damping),
        jnp.asarray(2.0),
        jnp.asarray(0),
        jnp.asarray(False),
    )


def update(
    state: LMState,
    trial,
    delta,
    predicted,
    new_residual,
    new_model,
    residual_scaled: bool = False,
) -> LMState:
    """The carry after the step ``delta`` to ``trial = x + δ`` (linearised there as
    ``(new_residual, new_model)``, its decrease of ``|C|²`` predicted as
    ``predicted``): accepted or rejected, with Nielsen's damping update, of the
    multiplier of ``|C|²`` where ``residual_scaled`` (module docstring)."""
    r, lam = state.residual, state.damping
    actual = r @ r - new_residual @ new_residual
    rho = actual / jnp.where(predicted > 0, predicted, 1.0)
    accept = (actual > 0) & (predicted > 0) & jnp.all(jnp.isfinite(new_residual))
    shrink = jnp.maximum(1.0 / 3.0, 1.0 - (2.0 * rho - 1.0) ** 3)
    size = jnp.sqrt(delta @ delta)
    tiny = size < MIN_STEP * (1.0 + jnp.sqrt(state.x @ state.x))
    return LMState(
        x=jnp.where(accept, trial, state.x),
        residual=jnp.where(accept, new_residual, r),
        model=jax.tree.map(
            lambda new, old: jnp.where(accept, new, old), new_model, state.model
        ),
        damping=jnp.where(
            accept,
            _lowered(lam * shrink, r, new_residual, residual_scaled),
            lam * state.growth,
        ),
        growth=jnp.where(accept, 2.0, 2.0 * state.growth),
        iteration=state.iteration + 1,
        stalled=(~accept & (lam * state.growth > MAX_DAMPING)) | (tiny & ~accept),
    )


def _lowered(nielsen, residual, new_residual, residual_scaled: bool):
    """The damping after an accepted step: Nielsen's ``nielsen``, times the fall of
    ``|C|²`` (not below :data:`MIN_DAMPING`) where ``residual_scaled``: ``μ = λ/|C|²``
    takes Nielsen's factor, so ``λ`` moves with ``|C|²``."""
    if not residual_scaled:
        return nielsen
    r2 = residual @ residual
    fall = (new_residual @ new_residual) / jnp.where(r2 > 0, r2, 1.0)
    return jnp.minimum(nielsen, jnp.maximum(nielsen * fall, MIN_DAMPING))


def solve(
    method: Method,
    x0,
    *,
    tolerance: float,
    max_iterations: int,
    initial_damping: float,
    residual_scaled: bool = False,
) -> LMResult:
    """Minimise ``½|C(x)|²`` from ``x0`` by ``method``'s steps; jit- and vmap-friendly,
    no NaN on failure; ``residual_scaled``: :class:`LevenbergMarquardt`'s."""
    solver = LevenbergMarquardt(method, tolerance, initial_damping, residual_scaled)
    state, _ = run(solver, x0, max_iterations)
    error = jnp.max(jnp.abs(state.residual))
    converged = error <= tolerance
    return LMResult(
        state.x,
        converged,
        jnp.where(jnp.isfinite(error), error, jnp.inf),
        state.iteration,
        (state.residual, state.model),
    )
