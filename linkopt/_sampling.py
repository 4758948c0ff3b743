"""IK samples (paper eq. 4) and adversarial samples (eq. 5) for one design.

Both minimise a function of the motor values ``a`` whose state ``s(a)`` is the forward
kinematics solution, with exact gradients through the implicit function theorem:
``ds/da = -(JᵀJ)⁻¹ Jᵀ ∂C_FK/∂a`` (including the singularity terms, where the paper used
finite differences). Everything is homogenised.

The minimiser (:func:`minimise`) is a damped quasi-Newton method on the 1-3 motor values:
step ``δ = -(H + λI)⁻¹ g`` with ``‖δ‖ ≤ r``, accepted on an Armijo decrease, else ``λ``
grows. ``H`` is the Gauss–Newton matrix of the reach residual for IK samples and a BFGS
estimate for adversarial samples (whose ``f_sing`` has no usable exact Hessian). Every
trial forward solve starts from the linear prediction ``s + (ds/da) δ``, and a trial is
rejected when the solved state departs from that prediction by more than half of
``(ds/da) δ``: that is how a step that crossed a forward singularity onto another
assembly branch shows up. The paper's BFGS with an unguarded step could cross (its
Fig. 4); this guard is our addition.

The step bound ``r`` is a trust radius: it starts at the file's ``max_step``, doubles
after an accepted step that it had to shorten (up to ``RADIUS_GROWTH · max_step``) and
halves after a rejected one (down to ``max_step``). Samples travel up to about 2 rad
from the rest pose, which at a fixed 0.1 rad took 20 of the 40 iterations before the
minimisation proper began. Iteration stops when the gradient is below ``GRADIENT_TOL``,
or when an accepted step that the radius did not shorten lowered the value by at most
``VALUE_RTOL`` of it (a converged quasi-Newton step: targets out of reach never get a
zero gradient), or at the iteration cap.
"""

from __future__ import annotations

from typing import Callable, NamedTuple

import jax
import jax.numpy as jnp
from jax.scipy.linalg import cho_factor, cho_solve
from jaxtyping import Array, Bool, Float, Int

from ._constraints import fk_residual, output_residual, output_values
from ._geometry import Geometry
from ._jacobian import state_jacobian
from ._kinematics import _solve_single
from ._metrics import Thresholds, attractive, barrier, culled
from ._model import Mechanism
from ._singularity import f_sing_value

ARMIJO = 1e-4
GRADIENT_TOL = 1e-9
VALUE_RTOL = 1e-9
RADIUS_GROWTH = 4.0
MAX_DAMPING = 1e8
BRANCH_TOL = 0.5
#: Iteration cap of a trial forward solve: from the linear prediction, a step of at most
#: ``RADIUS_GROWTH · max_step`` converges in 2-4 LM iterations; one that needs more is
#: rejected, since under ``vmap`` a lane that ran on to a longer cap would hold up every
#: other sample.
TRIAL_ITERATIONS = 6


class Sample(NamedTuple):
    motors: Float[Array, " M"]  # homogenised
    state: Float[Array, " S"]
    value: Float[Array, ""]
    iterations: Int[Array, ""]


class _Iterate(NamedTuple):
    motors: Float[Array, " M"]
    state: Float[Array, " S"]
    value: Float[Array, ""]
    gradient: Float[Array, " M"]
    hessian: Float[Array, "M M"]
    ds_da: Float[Array, "S M"]
    damping: Float[Array, ""]
    radius: Float[Array, ""]
    iteration: Int[Array, ""]
    done: Bool[Array, ""]


def state_motor_jacobian(mech: Mechanism, geom: Geometry, motors, state) -> Float[Array, "S M"]:
    """``ds/da`` at a solved state (eq. 2, least-squares form for tall Jacobians)."""
    jac_s = state_jacobian(mech, geom, "fk", state)
    jac_a = jax.jacfwd(lambda a: fk_residual(mech, geom, a, state))(motors)
    return -cho_solve(cho_factor(jac_s.T @ jac_s), jac_s.T @ jac_a)


# An objective maps (motors, state) to (value, ∂/∂s, ∂/∂a, Gauss–Newton matrix or None).
Objective = Callable[[Float[Array, " M"], Float[Array, " S"], Float[Array, "S M"]], tuple]


def _evaluate(objective, mech, geom, motors, state):
    ds_da = state_motor_jacobian(mech, geom, motors, state)
    value, gradient, model = objective(motors, state, ds_da)
    return value, gradient, model, ds_da


def minimise(mech: Mechanism, geom: Geometry, objective, motors0, state0, iterations: int, bfgs: bool) -> Sample:
    """Minimise ``objective`` over motors from a solved ``(motors0, state0)`` (see module doc)."""
    settings = mech.evaluation
    value, gradient, model, ds_da = _evaluate(objective, mech, geom, motors0, state0)
    size = motors0.shape[0]
    start_hessian = jnp.eye(size) if bfgs else model
    max_step = settings.max_step
    it0 = _Iterate(motors0, state0, value, gradient, start_hessian, ds_da, jnp.asarray(1e-6), jnp.asarray(max_step), jnp.asarray(0), jnp.asarray(False))

    def step(it: _Iterate) -> _Iterate:
        system = it.hessian + it.damping * jnp.eye(size)
        delta = -jnp.linalg.solve(system, it.gradient)
        norm = jnp.sqrt(delta @ delta)
        shortened = norm > it.radius
        delta = delta * jnp.minimum(1.0, it.radius / jnp.maximum(norm, 1e-300))
        predicted = it.ds_da @ delta
        trial = _solve_single(mech, "fk", geom, it.motors + delta, it.state + predicted, TRIAL_ITERATIONS)
        departure = jnp.sqrt(jnp.sum((trial.state - it.state - predicted) ** 2))
        on_branch = departure <= BRANCH_TOL * jnp.sqrt(predicted @ predicted) + 1e-10
        value, gradient, model, ds_da = _evaluate(objective, mech, geom, it.motors + delta, trial.state)
        decrease = value <= it.value + ARMIJO * (it.gradient @ delta)
        accept = trial.converged & on_branch & decrease & jnp.isfinite(value)
        if bfgs:
            y = gradient - it.gradient
            curvature = y @ delta
            hb = it.hessian @ delta
            updated = it.hessian - jnp.outer(hb, hb) / (delta @ hb) + jnp.outer(y, y) / jnp.where(curvature > 0, curvature, 1.0)
            model = jnp.where(curvature > 1e-12, updated, it.hessian)
        pick = lambda new, old: jnp.where(accept, new, old)  # noqa: E731
        damping = jnp.where(accept, jnp.maximum(it.damping / 3.0, 1e-9), it.damping * 4.0 + 1e-6)
        radius = jnp.where(accept, jnp.where(shortened, jnp.minimum(2.0 * it.radius, RADIUS_GROWTH * max_step), it.radius), jnp.maximum(it.radius / 2.0, max_step))
        small = jnp.max(jnp.abs(pick(gradient, it.gradient))) < GRADIENT_TOL
        stalled = accept & ~shortened & (it.value - value <= VALUE_RTOL * jnp.abs(value))
        return _Iterate(
            motors=pick(it.motors + delta, it.motors),
            state=pick(trial.state, it.state),
            value=pick(value, it.value),
            gradient=pick(gradient, it.gradient),
            hessian=pick(model, it.hessian),
            ds_da=pick(ds_da, it.ds_da),
            damping=damping,
            radius=radius,
            iteration=it.iteration + 1,
            done=small | stalled | (damping > MAX_DAMPING),
        )

    final = jax.lax.while_loop(lambda it: ~it.done & (it.iteration < iterations), step, it0)
    return Sample(final.motors, final.state, final.value, final.iteration)


def ik_objective(mech: Mechanism, geom: Geometry, target, th: Thresholds):
    """Eq. 4: ``f_BK(b^t, s(a)) + f_sing^c(s(a))`` with its Gauss–Newton model."""

    def parts(state):
        residual = output_residual(mech, geom, target, state)
        return 0.5 * residual @ residual + culled(f_sing_value(mech, geom, state), th), residual

    def objective(motors, state, ds_da):
        (value, residual), d_state = jax.value_and_grad(parts, has_aux=True)(state)
        # ∂r/∂s · ds/da as M forward tangents along the columns of ds/da
        jac = jax.jacfwd(lambda d: output_residual(mech, geom, target, state + ds_da @ d))(jnp.zeros(ds_da.shape[1]))
        return value, d_state @ ds_da, jac.T @ jac

    return objective


def adversarial_objective(mech: Mechanism, geom: Geometry, anchor_motors, low, high, th: Thresholds):
    """Eq. 5: ``f_sing^a(s) + w₁ ½|a - a_IK|² + w₂ R₂(s)``."""
    w_motion, w_range = mech.evaluation.motion_weight, mech.evaluation.range_weight

    def of_state(state):
        return attractive(f_sing_value(mech, geom, state), th) + w_range * barrier(output_values(mech, geom, state), low, high)

    def objective(motors, state, ds_da):
        value, d_state = jax.value_and_grad(of_state)(state)
        offset = motors - anchor_motors
        return value + 0.5 * w_motion * offset @ offset, d_state @ ds_da + w_motion * offset, None

    return objective
