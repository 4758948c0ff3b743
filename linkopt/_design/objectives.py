"""The objectives the sample queue minimises (:mod:`.sampling`): reaching an IK target,
the adversarial search for a low f_sing (paper Sec. IV), the least clearance between
links, and the choice of one of two per lane.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from .._engine.collision import capsule_gaps
from .._engine.constraints import (
    homogenised_output_values,
    output_residual,
)
from .._engine.geometry import Geometry
from .._engine.model import Mechanism
from .metrics import Thresholds, attractive, barrier, culled
from .sampling import Objective


def ik_objective(mech: Mechanism, geom: Geometry, target, th: Thresholds) -> Objective:
    """Eq. 4: ``f_BK(b^t, s(a)) + f_sing^c(s(a))`` with its Gauss–Newton model."""

    def objective(motors, state, ds_da, f_sing, d_f_sing):
        residual = output_residual(mech, geom, target, state)
        # ∂r/∂s · ds/da as M forward tangents along the columns of ds/da
        jac = jax.jacfwd(
            lambda d: output_residual(mech, geom, target, state + ds_da @ d)
        )(jnp.zeros(ds_da.shape[1]))
        term, slope = jax.value_and_grad(culled)(f_sing, th)
        return (
            0.5 * residual @ residual + term,
            jac.T @ residual + slope * (d_f_sing @ ds_da),
            jac.T @ jac,
        )

    return objective


def adversarial_objective(
    mech: Mechanism, geom: Geometry, anchor_motors, low, high, th: Thresholds
) -> Objective:
    """Eq. 5: ``f_sing^a(s) + w₁ ½|a - a_IK|² + w₂ R₂(s)``."""
    w_motion, w_range = mech.evaluation.motion_weight, mech.evaluation.range_weight

    def objective(motors, state, ds_da, f_sing, d_f_sing):
        term, slope = jax.value_and_grad(attractive)(f_sing, th)
        wall, d_wall = jax.value_and_grad(
            lambda s: barrier(homogenised_output_values(mech, geom, s), low, high)
        )(state)
        offset = motors - anchor_motors
        value = term + w_range * wall + 0.5 * w_motion * offset @ offset
        gradient = (slope * d_f_sing + w_range * d_wall) @ ds_da + w_motion * offset
        return value, gradient, jnp.zeros((motors.shape[0],) * 2)

    return objective


def clearance_objective(
    mech: Mechanism, geom: Geometry, anchor_motors, low, high
) -> Objective:
    """The collision samples' search (:mod:`linkopt._design.evaluation`):
    eq. 5 with the soft minimum of the checked capsule pairs' clearances ``g_i`` in
    place of ``f_sing^a``, ``-c log Σ exp(-g_i / c)`` with ``c`` the clearance band,
    plus ``w₁ ½|a - a_IK|² + w₂ R₂(s)``. Its minimum is a pose near the IK sample, in
    the target range, where the links come closest; unlike the barrier of the
    collision term it has a gradient at any distance, so the search also finds the
    closest pose of a design that is clear. Homogenised lengths."""
    w_motion, w_range = mech.evaluation.motion_weight, mech.evaluation.range_weight
    band = mech.collision.clearance / mech.length_scale

    def closest(state):
        gaps = capsule_gaps(mech, geom, state)
        return -band * jax.scipy.special.logsumexp(-gaps / band)

    def objective(motors, state, ds_da, f_sing, d_f_sing):
        gap, d_gap = jax.value_and_grad(closest)(state)
        wall, d_wall = jax.value_and_grad(
            lambda s: barrier(homogenised_output_values(mech, geom, s), low, high)
        )(state)
        offset = motors - anchor_motors
        value = gap + w_range * wall + 0.5 * w_motion * offset @ offset
        gradient = (d_gap + w_range * d_wall) @ ds_da + w_motion * offset
        return value, gradient, jnp.zeros((motors.shape[0],) * 2)

    return objective


def either(first: Objective, second: Objective, use_second) -> Objective:
    """The objective ``second`` where the traced ``use_second`` holds, else ``first``
    (both are computed: the shared ``f_sing`` makes the rest cheap)."""

    def objective(*args):
        return jax.tree_util.tree_map(
            lambda a, b: jnp.where(use_second, b, a), first(*args), second(*args)
        )

    return objective
