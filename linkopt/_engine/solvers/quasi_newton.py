"""A damped trust-region quasi-Newton method on a few variables whose every point costs
an expensive, fallible evaluation (the design layer's samples,
:mod:`linkopt._design.sampling`, where a point is a forward solve).

Step ``δ = -(H + λI)⁻¹ g`` with ``‖δ‖ ≤ r``, accepted on an Armijo decrease when the
problem's trial at ``x + δ`` succeeds, else ``λ`` grows. ``H`` is the problem's
Gauss–Newton matrix, or a BFGS estimate (``bfgs``; kept where the curvature is not
positive). The trust radius ``r`` starts at ``max_step``, doubles after an accepted step
that it had to shorten (up to ``RADIUS_GROWTH · max_step``) and halves after a rejected
one (down to ``max_step``). Iteration stops when the gradient is below
``GRADIENT_TOL``, when an accepted step that the radius did not shorten lowered the
value by at most ``VALUE_RTOL`` of it (a converged step: a target out of reach never
gets a zero gradient), or when the damping passes ``MAX_DAMPING`` (stalled).

A state that is ``fresh`` is a start point not evaluated yet: its next :meth:`step` has
length zero and is accepted, and makes it the start of a minimisation (Gauss–Newton
matrix or the identity, initial damping and radius, iteration 0). Starting and stepping
are one function so that a compiled loop holds the expensive evaluation once; a batch
of minimisations can restart one lane by setting its ``fresh``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Protocol

import jax
import jax.numpy as jnp
from jaxtyping import Array, Bool, Float, Int

from .. import dense_lu
from .driver import Result

ARMIJO = 1e-4
GRADIENT_TOL = 1e-9
VALUE_RTOL = 1e-9
RADIUS_GROWTH = 4.0
MAX_DAMPING = 1e8
INITIAL_DAMPING = 1e-6


@jax.tree_util.register_dataclass
@dataclass(frozen=True)
class QNState:
    x: Float[Array, " M"]
    point: Any  # the problem's data at x (its ``evaluate``'s last output)
    value: Float[Array, ""]
    gradient: Float[Array, " M"]
    hessian: Float[Array, "M M"]
    damping: Float[Array, ""]
    radius: Float[Array, ""]
    iteration: Int[Array, ""]
    done: Bool[Array, ""]
    result: Int[Array, ""]  # why it is done (a driver ``Result``)
    fresh: Bool[Array, ""]  # the next step starts a minimisation here


class Problem(Protocol):
    def trial(self, state: QNState, delta, fresh) -> tuple[Any, Bool[Array, ""]]:
        """The trial at ``state.x + delta`` (the state's own point when ``fresh``)
        and whether it may be accepted."""

    def evaluate(self, x, trial) -> tuple[Any, Any, Any, Any]:
        """``(value, gradient, Gauss–Newton matrix, point)`` at a trial."""


class Bounds(Protocol):
    """A box on ``x``: a step holds pinned variables, stays inside, and a gradient that
    pushes against a bound is spent."""

    def hold(self, x, system, gradient) -> tuple: ...

    def clip(self, x, delta): ...

    def spent(self, x, gradient): ...


def unevaluated(x0: Float[Array, " M"], point: Any) -> QNState:
    """A fresh state at ``x0`` whose value is not computed yet (module docstring);
    ``point`` is the problem's data at ``x0`` as far as its trial needs it."""
    size, zero = x0.shape[0], jnp.zeros(())
    return QNState(
        x0,
        point,
        zero,
        jnp.zeros(size),
        jnp.eye(size),
        zero,
        zero,
        jnp.asarray(0),
        jnp.asarray(False),
        jnp.asarray(Result.SUCCESSFUL),
        jnp.asarray(True),
    )


@dataclass(frozen=True)
class QuasiNewton:
    """The method of the module docstring on ``problem``; ``bfgs`` may be traced."""

    problem: Problem
    max_step: Any
    bfgs: Any = False
    bounds: Bounds | None = None  # static: without bounds none of it is traced

    def init(self, y0) -> QNState:
        """``y0 = (x0, point)``: the start, evaluated."""
        return self.step(unevaluated(*y0))

    def terminate(self, state: QNState):
        return state.done, state.result

    def direction(self, state: QNState) -> tuple:
        """The damped step within the trust radius (zero when fresh), and whether the
        radius shortened it."""
        fresh = state.fresh
        size = state.x.shape[0]
        system = state.hessian + state.damping * jnp.eye(size)
        gradient = state.gradient
        if self.bounds is not None:
            system, gradient = self.bounds.hold(state.x, system, gradient)
        delta = -dense_lu.solve(system, gradient)  # LU, as jnp.linalg.solve
        norm = jnp.sqrt(delta @ delta)
        shortened = norm > state.radius
        scale = jnp.minimum(1.0, state.radius / jnp.maximum(norm, 1e-300))
        delta = jnp.where(fresh, 0.0, delta * scale)
        if self.bounds is not None:
            delta = self.bounds.clip(state.x, delta)
        return delta, shortened

    def step(self, state: QNState) -> QNState:
        fresh = state.fresh
        delta, shortened = self.direction(state)
        trial, ok = self.problem.trial(state, delta, fresh)
        value, gradient, model, point = self.problem.evaluate(state.x + delta, trial)
        decrease = value <= state.value + ARMIJO * (state.gradient @ delta)
        accept = fresh | (ok & decrease & jnp.isfinite(value))
        quasi_newton = _bfgs(state, delta, gradient)
        eye = jnp.eye(state.x.shape[0])
        model = jnp.where(self.bfgs, jnp.where(fresh, eye, quasi_newton), model)

        def pick(new, old):
            return jax.tree.map(lambda n, o: jnp.where(accept, n, o), new, old)

        damping, radius = _trust(state, accept, shortened, self.max_step)
        kept = pick(gradient, state.gradient)
        if self.bounds is not None:  # a gradient that pushes against a bound is spent
            kept = self.bounds.spent(pick(state.x + delta, state.x), kept)
        small = jnp.max(jnp.abs(kept)) < GRADIENT_TOL
        stalled = (
            accept & ~shortened & (state.value - value <= VALUE_RTOL * jnp.abs(value))
        )
        failed = damping > MAX_DAMPING
        return QNState(
            x=pick(state.x + delta, state.x),
            point=pick(point, state.point),
            value=pick(value, state.value),
            gradient=pick(gradient, state.gradient),
            hessian=pick(model, state.hessian),
            damping=jnp.where(fresh, INITIAL_DAMPING, damping),
            radius=jnp.where(fresh, self.max_step, radius),
            iteration=jnp.where(fresh, 0, state.iteration + 1),
            done=~fresh & (small | stalled | failed),
            result=jnp.where(small | stalled, Result.SUCCESSFUL, Result.STALLED),
            fresh=jnp.zeros_like(fresh),
        )


def _bfgs(state: QNState, delta, gradient) -> Float[Array, "M M"]:
    """The BFGS update of the Hessian estimate, kept where the curvature is not
    positive."""
    y = gradient - state.gradient
    curvature = y @ delta
    hb = state.hessian @ delta
    updated = (
        state.hessian
        - jnp.outer(hb, hb) / (delta @ hb)
        + jnp.outer(y, y) / jnp.where(curvature > 0, curvature, 1.0)
    )
    return jnp.where(curvature > 1e-12, updated, state.hessian)


def _trust(state: QNState, accept, shortened, max_step) -> tuple:
    """The next damping and trust radius (module docstring)."""
    damping = jnp.where(
        accept, jnp.maximum(state.damping / 3.0, 1e-9), state.damping * 4.0 + 1e-6
    )
    radius = jnp.where(
        accept,
        jnp.where(
            shortened,
            jnp.minimum(2.0 * state.radius, RADIUS_GROWTH * max_step),
            state.radius,
        ),
        jnp.maximum(state.radius / 2.0, max_step),
    )
    return damping, radius
