"""Partial gradient of the design objective (paper Sec. V).

``∂/∂p [f_design + regulariser]`` with the IK and adversarial motor values *frozen*:
each sample's state ``s(p)`` solves ``C_FK(s, p; a) = 0`` at its frozen motors ``a``, so
by the implicit function theorem ``ds/dp = -(JᵀJ)⁻¹ Jᵀ ∂C/∂p`` with ``J = ∂C/∂s``.

We never differentiate through a solve. For a sample term ``g(s, p)`` the chain rule
``dg/dp = ∂g/∂p + ∂g/∂s · ds/dp`` is the adjoint form
``dg/dp = ∂/∂p [g(s, p) - μᵀ C(s, p)]`` at fixed ``s``, with ``μ = J (JᵀJ)⁻¹ ∂g/∂s``
(one small linear solve per sample). The samples' states are already solved at the
evaluated design, so no forward solve is needed at all; :func:`frozen_lagrangian` is
the scalar whose ``p``-gradient is the partial gradient (each sample's ``∂g/∂p``
enters through the geometry as ``⟨∂g/∂x, x(p)⟩``, :func:`adjoint_term`). This keeps
the batched gradient a straight-line program, quick to compile, where reverse mode
through the LM while-loops of :func:`frozen_objective` under ``vmap`` compiled far
too slowly. :func:`frozen_objective` (which re-solves) stays as the reference for the
tests.

With ``[collision]`` enabled, each IK sample term also carries its half of the
weighted collision term (:mod:`linkopt._design.evaluation`), and each collision sample
(its motors frozen too) adds the other half, so the term's design gradient comes
through the same adjoint: it moves with the design both through the capsules'
anchors (``∂g/∂p``) and through the sample's state (``μ``). Without it, the terms are
as they were.
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp

from .._engine import banded, dense, programs
from .._engine.collision import collision_value, has_collision
from .._engine.constraints import fk_residual, output_residual
from .._engine.geometry import geometry
from .._engine.jacobian import state_jacobian
from .._engine.kinematics import solve_single
from .._engine.lifting import padded_design
from .._engine.model import Mechanism
from .._engine.singularity import f_sing_value
from .evaluation import (
    Evaluation,
    batch_arguments,
    evaluate_homogenised,
    regularizer,
    targets,
)
from .metrics import culled, thresholds


def _collision_term(mech: Mechanism, state, geom):
    """A sample's half of the weighted collision term (module docstring)."""
    return 0.5 * mech.collision.weight * collision_value(mech, geom, state)


def _with_collision(mech: Mechanism, term):
    """``term`` plus the sample's half of the weighted collision term, when the file
    checks collisions (module docstring); ``term`` itself otherwise."""
    if not has_collision(mech):
        return term
    return lambda state, geom: term(state, geom) + _collision_term(mech, state, geom)


def _reach_term(mech: Mechanism, goal):
    def term(state, geom):
        residual = output_residual(mech, geom, goal, state)
        return 0.5 * residual @ residual

    return _with_collision(mech, term)


def _singular_term(mech: Mechanism, th):
    return lambda state, geom: culled(f_sing_value(mech, geom, state), th)


def frozen_objective(
    mech: Mechanism, design, evaluation: Evaluation, alpha
) -> jax.Array:
    """``f_design + regulariser`` at ``design`` with the samples' motors held fixed
    (re-solving each sample's forward kinematics at ``design``)."""
    geom = geometry(mech, design)
    th = thresholds(alpha)
    goals = jnp.asarray(targets(mech) / mech.output_scale)

    def solved(motors, start):
        return solve_single(
            mech,
            "fk",
            geom,
            jax.lax.stop_gradient(motors),
            jax.lax.stop_gradient(start),
        ).state

    f_reach = jax.vmap(lambda g, a, s: _reach_term(mech, g)(solved(a, s), geom))(
        goals, evaluation.ik_motors, evaluation.ik_states
    )
    f_sing = jax.vmap(lambda a, s: _singular_term(mech, th)(solved(a, s), geom))(
        evaluation.adv_motors, evaluation.adv_states
    )
    if has_collision(mech):
        f_sing = f_sing + jax.vmap(
            lambda a, s: _collision_term(mech, solved(a, s), geom)
        )(evaluation.col_motors, evaluation.col_states)
    return jnp.mean(f_reach + f_sing) + regularizer(mech, design)


def adjoint_term(mech: Mechanism, term, design, motors, state):
    """A scalar whose ``p``-gradient is that of ``g(s, p) - μᵀ C_FK(s, p; a)`` with
    ``μ`` held fixed (module docstring): ``⟨∂g/∂x, x(p)⟩ - μᵀ C_FK(s, x(p); a)``, where
    ``x(p)`` is the design's geometry and ``∂g/∂x`` is taken once, in the same reverse
    pass as ``∂g/∂s``. Differentiating ``g`` again through ``x(p)`` (the form before)
    ran the sample term, σ_min and all, forward and backward twice per sample, in the
    program and in its compile time (``benchmarks/bench_compile.py``). The value is
    not ``g``; only the gradient is used. Where the solves take the band
    (:func:`linkopt._engine.banded.serves`), ``μ`` comes from the banded factor
    (:func:`linkopt._engine.banded.adjoint_multiplier`) and σ_min in ``g`` from
    :mod:`linkopt._engine.banded_sigma`: no dense Jacobian, cost linear in the
    bodies."""
    motors = jax.lax.stop_gradient(motors)
    state = jax.lax.stop_gradient(state)
    geom = geometry(mech, design)
    fixed = jax.lax.stop_gradient(geom)
    d_state, d_geom = jax.grad(term, argnums=(0, 1))(state, fixed)
    if banded.serves(mech):  # static; built from `fixed`: no gradient
        mu = banded.adjoint_multiplier(mech, fixed, motors, state, d_state)
    else:
        jac = state_jacobian(mech, fixed, "fk", state)
        mu = jac @ dense.solve_spd(jac.T @ jac, d_state)  # from `fixed`: no gradient
    leaves = zip(jax.tree.leaves(d_geom), jax.tree.leaves(geom))
    direct = sum(jnp.vdot(g, x) for g, x in leaves)
    return direct - mu @ fk_residual(mech, geom, motors, state)


def frozen_lagrangian(
    mech: Mechanism, design, evaluation: Evaluation, alpha
) -> jax.Array:
    """Scalar whose gradient in ``design`` is the partial gradient (module
    docstring); its value is not the objective."""
    th = thresholds(alpha)
    goals = jnp.asarray(targets(mech) / mech.output_scale)
    reach = jax.vmap(
        lambda g, a, s: adjoint_term(mech, _reach_term(mech, g), design, a, s)
    )
    sing = jax.vmap(
        lambda a, s: adjoint_term(mech, _singular_term(mech, th), design, a, s)
    )
    f_reach = reach(goals, evaluation.ik_motors, evaluation.ik_states)
    f_sing = sing(evaluation.adv_motors, evaluation.adv_states)
    if has_collision(mech):  # static
        term = functools.partial(_collision_term, mech)
        closest = jax.vmap(lambda a, s: adjoint_term(mech, term, design, a, s))
        f_sing = f_sing + closest(evaluation.col_motors, evaluation.col_states)
    return jnp.mean(f_reach + f_sing) + regularizer(mech, design)


def gradients_homogenised(mech: Mechanism, designs, evaluation: Evaluation, alpha):
    """The jitted core of :func:`partial_gradient`: homogenised designs, a given α₋."""
    grad = jax.grad(lambda p, ev: frozen_lagrangian(mech, p, ev, alpha))
    if designs.ndim == 1:
        return grad(designs, evaluation)
    return jax.vmap(grad)(designs, evaluation)


def partial_gradient(mech: Mechanism, designs, evaluation: Evaluation, alpha: float):
    """Partial gradients ``(n_p,)`` or ``(N, n_p)`` for designs evaluated as
    ``evaluation`` (file units: per unit of each design parameter)."""
    evaluation = jax.tree_util.tree_map(
        lambda v: jnp.asarray(v, dtype=jnp.float64), evaluation
    )
    alpha = jnp.asarray(alpha, dtype=jnp.float64)
    gradients = programs.call(
        "partial_gradient",
        mech,
        gradients_homogenised,
        padded_design(mech, designs),
        evaluation,
        alpha,
    )
    return gradients[..., : mech.design.size]  # the padding's entries are zero


def _chunk_arguments(mech: Mechanism, rows: int) -> tuple:
    """Zeros shaped as :func:`partial_gradient`'s arguments for a chunk of ``rows``
    designs (the evaluation's shapes read off its program, which is not run)."""
    designs, alpha = batch_arguments(mech, rows)
    shapes = programs.output_shapes(
        "evaluate", mech, evaluate_homogenised, designs, alpha
    )
    evaluation = jax.tree_util.tree_map(
        lambda s: jnp.zeros(s.shape, dtype=jnp.float64), shapes
    )
    return designs, evaluation, alpha


def compile_gradient(mech: Mechanism, rows: int) -> None:
    """Compile the partial gradient of a chunk of ``rows`` designs into the persistent
    cache without running it (:func:`linkopt._engine.programs.compile_ahead`)."""
    programs.compile_ahead(
        "partial_gradient", mech, gradients_homogenised, *_chunk_arguments(mech, rows)
    )
