"""Forward and backward kinematics solves, continuation paths and implicit
sensitivities.

Public functions take motor values ``a`` and outputs ``b`` in file units (rad for
angles) and return homogenised states. Every solve is jitted with the mechanism as a
static argument; a leading batch axis on ``a``/``b`` (and optionally the start state)
is vmapped, so a batch never recompiles for a new design vector.

Derivatives (paper eq. 2): the solved state is attached to its inputs by
:func:`implicit_state`, whose JVP is the implicit-function-theorem tangent
``ṡ = -(JᵀJ)⁻¹ Jᵀ (∂C/∂a ȧ + ∂C/∂p ṗ)`` with ``J = ∂C/∂s``. For ``f_FK = 0`` this is
eq. 2 (the Gauss–Newton Hessian is exact there); with redundant rows ``J`` is tall and
the formula is the least-squares tangent. Both forward and reverse mode work through it.
"""

from __future__ import annotations

from functools import partial
from typing import NamedTuple

import jax
import jax.numpy as jnp
from jax.scipy.linalg import cho_factor, cho_solve
from jaxtyping import Array, Bool, Float, Int

from . import jacobian, lm
from .constraints import bk_residual, fk_residual
from .geometry import Geometry, design_vector, geometry, rest_state
from .model import Mechanism

_RESIDUALS = {"fk": fk_residual, "bk": bk_residual}


class Solution(NamedTuple):
    """A kinematics solve; leading axes follow the batch/path of the inputs."""

    state: Float[Array, "... S"]  # homogenised state
    converged: Bool[Array, ...]
    residual: Float[Array, ...]  # max |C| at state (homogenised)
    iterations: Int[Array, ...]


@partial(jax.custom_jvp, nondiff_argnums=(0, 1))
def implicit_state(mech: Mechanism, kind: str, geom: Geometry, values, state):
    """Identity on ``state``; carries the implicit-function derivative (module
    docstring)."""
    return state


@implicit_state.defjvp
def _implicit_state_jvp(mech, kind, primals, tangents):
    geom, values, state = primals
    d_geom, d_values, _ = tangents
    residual = _RESIDUALS[kind]
    _, rhs = jax.jvp(
        lambda g, v: residual(mech, g, v, state), (geom, values), (d_geom, d_values)
    )
    jac = jacobian.state_jacobian(mech, geom, kind, state)
    d_state = -cho_solve(cho_factor(jac.T @ jac), jac.T @ rhs)
    return state, d_state


def solve_single(
    mech: Mechanism,
    kind: str,
    geom: Geometry,
    values,
    start,
    max_iterations: int | None = None,
) -> Solution:
    """One LM solve of ``C(values, s) = 0`` from ``start`` (all homogenised); the
    iteration cap defaults to the file's ``[solver] max_iterations``."""
    fixed_geom = jax.lax.stop_gradient(geom)
    fixed_values = jax.lax.stop_gradient(values)
    settings = mech.solver
    result = lm.solve(
        lambda s: _RESIDUALS[kind](mech, fixed_geom, fixed_values, s),
        jax.lax.stop_gradient(start),
        tolerance=settings.tolerance,
        max_iterations=max_iterations or settings.max_iterations,
        initial_damping=settings.initial_damping,
        linearise=lambda s: jacobian.normal_equations(
            mech, fixed_geom, kind, fixed_values, s
        ),
    )
    state = implicit_state(mech, kind, geom, values, result.x)
    return Solution(state, result.converged, result.residual, result.iterations)


def _scale(mech: Mechanism, kind: str):
    return mech.motor_scale if kind == "fk" else mech.output_scale


def _prepare(mech: Mechanism, kind: str, values, start, design):
    values = jnp.asarray(values, dtype=jnp.float64) / _scale(mech, kind)
    start = rest_state(mech) if start is None else jnp.asarray(start, dtype=jnp.float64)
    return values, start, geometry(mech, design_vector(mech, design))


@partial(jax.jit, static_argnums=(0, 1))
def _solve(mech: Mechanism, kind: str, values, start, design) -> Solution:
    values, start, geom = _prepare(mech, kind, values, start, design)
    if values.ndim == 1:
        return solve_single(mech, kind, geom, values, start)
    in_start = 0 if start.ndim == 2 else None
    return jax.vmap(
        lambda v, s0: solve_single(mech, kind, geom, v, s0), in_axes=(0, in_start)
    )(values, start)


@partial(jax.jit, static_argnums=(0, 1))
def _solve_path(mech: Mechanism, kind: str, values, start, design) -> Solution:
    values, start, geom = _prepare(mech, kind, values, start, design)

    def advance(previous, v):
        solution = solve_single(mech, kind, geom, v, previous)
        return jnp.where(solution.converged, solution.state, previous), solution

    _, solutions = jax.lax.scan(advance, start, values)
    return solutions


def solve_fk(mech: Mechanism, motors, *, start=None, design=None) -> Solution:
    """Forward kinematics: motors ``(M,)`` or a batch ``(N, M)`` -> states.

    ``start`` is the warm start (homogenised state ``(S,)`` or ``(N, S)``; default the
    rest state); ``design`` the design vector (default the file's). Differentiable in
    ``motors`` and ``design`` through the implicit function theorem.
    """
    return _solve(mech, "fk", motors, start, design)


def solve_bk(mech: Mechanism, outputs, *, start=None, design=None) -> Solution:
    """Backward kinematics: outputs ``(K,)`` or ``(N, K)`` -> states (motors read off
    them)."""
    return _solve(mech, "bk", outputs, start, design)


def solve_fk_path(mech: Mechanism, motors, *, start=None, design=None) -> Solution:
    """Continuation along motor values ``(T, M)``: each solve starts from the last
    converged state, so the mechanism stays on the assembly branch of ``start``."""
    return _solve_path(mech, "fk", motors, start, design)


def solve_bk_path(mech: Mechanism, outputs, *, start=None, design=None) -> Solution:
    """Continuation along outputs ``(T, K)``, as :func:`solve_fk_path`."""
    return _solve_path(mech, "bk", outputs, start, design)


def sensitivity(
    mech: Mechanism, state, wrt: str, *, design=None
) -> Float[Array, "S n"]:
    """``ds/da`` (``wrt="motors"``), ``ds/db`` (``"outputs"``), or ``ds/dp`` at fixed
    motors (``"design"``) or fixed outputs (``"design_bk"``), at a solved homogenised
    state.

    Motors, outputs and design are in file units, so e.g. ``ds/da`` of a linear motor is
    per file length unit.
    """
    from .readout import motor_values, output_values  # local: avoid an import cycle

    p = design_vector(mech, design)
    state = jnp.asarray(state, dtype=jnp.float64)
    if wrt == "motors":
        a = motor_values(mech, state, design=p)
        return jax.jacfwd(lambda v: solve_fk(mech, v, start=state, design=p).state)(a)
    if wrt == "outputs":
        b = output_values(mech, state, design=p)
        return jax.jacfwd(lambda v: solve_bk(mech, v, start=state, design=p).state)(b)
    if wrt == "design":
        a = motor_values(mech, state, design=p)
        return jax.jacfwd(lambda q: solve_fk(mech, a, start=state, design=q).state)(p)
    if wrt == "design_bk":
        b = output_values(mech, state, design=p)
        return jax.jacfwd(lambda q: solve_bk(mech, b, start=state, design=q).state)(p)
    raise ValueError(
        f"wrt must be 'motors', 'outputs', 'design' or 'design_bk', not {wrt!r}"
    )
