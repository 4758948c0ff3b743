"""Gauss–Newton projection onto the nearest point of ``{x : C(x) = 0}``.

From a point on the set (``C(x) ≈ 0``), find the point of the set nearest an anchor
``x₀`` in the weighted norm ``|S⁻¹(x - x₀)|`` (``S = diag(scale)``, ``scale`` 0 holds a
variable): each step moves the weighted variables ``y = S⁻¹x`` to the least-norm
solution of the linearised problem,

    ``min |y + d - y₀|  subject to  C + Jₛ d = 0``,   ``Jₛ = J S``,

that is ``d = -(y - y₀) + Jₛᵀ (Jₛ Jₛᵀ + μI)⁻¹ (Jₛ (y - y₀) - C)``, with ``μ`` tiny
against redundant rows. It stops when a step moves no variable by more than
``MIN_STEP`` (the linkage's assembly, :mod:`linkopt._files.assembly.solve`, polishes
the result with Levenberg–Marquardt after it).
"""

from __future__ import annotations

from dataclasses import dataclass

import jax
import jax.numpy as jnp
from jaxtyping import Array, Bool, Float, Int

from .driver import Result
from .lm import MinimumNorm, gram_solve

MIN_STEP = 1e-15
#: ``μ``: the damping of the least-norm solve.
DAMPING = 1e-14


@jax.tree_util.register_dataclass
@dataclass(frozen=True)
class ProjectionState:
    x: Float[Array, " n"]
    iteration: Int[Array, ""]
    small: Bool[Array, ""]  # the last step moved no variable by more than MIN_STEP


@dataclass(frozen=True)
class Projection:
    """Project onto ``{C = 0}`` nearest ``anchor`` in the norm weighted by ``scale``
    (module docstring); ``linearisation`` is ``C`` and ``Jₛ``."""

    linearisation: MinimumNorm
    anchor: Float[Array, " n"]

    def init(self, x0) -> ProjectionState:
        return ProjectionState(x0, jnp.asarray(0), jnp.asarray(False))

    def step(self, state: ProjectionState) -> ProjectionState:
        s, x = self.linearisation.scale, state.x
        r, jac = self.linearisation.linearise(x)
        delta = jnp.where(s > 0, (x - self.anchor) / jnp.where(s > 0, s, 1.0), 0.0)
        _, u = gram_solve(jac, DAMPING, jac @ delta - r)
        dx = s * (-delta + jac.T @ u)
        small = jnp.max(jnp.abs(dx)) < MIN_STEP
        return ProjectionState(x + dx, state.iteration + 1, small)

    def terminate(self, state: ProjectionState):
        return state.small, jnp.asarray(Result.SUCCESSFUL)
