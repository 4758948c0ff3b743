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

Under ``vmap`` a ``while_loop`` steps every lane until the last one stops, so a batch
costs its slowest lane's iterations times its width. :func:`minimise_queue` runs ``L``
lanes through ``width`` slots instead: a slot whose lane has stopped takes the next
waiting lane at once, and each lane takes the steps it takes in :func:`minimise` (the
flat batch rounds differently from nested ``vmap``: samples agree to about 5e-11).
It pays where iteration counts are spread: five-bar IK lanes from the rest pose stop
after 5-12 iterations when their target is reachable and run to the cap of 40 when it
is not, and 90 IK lanes (10 designs) through 45 slots took 0.15 s less than under
``vmap`` (1.23 s → 1.06 s for the whole evaluation; 28 or 45 slots made no difference).
Adversarial lanes stop after 14-40 iterations with most near the cap, where a queue of
fixed width only adds a tail, so they stay under ``vmap``.
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


def _start(mech: Mechanism, geom: Geometry, objective, motors0, state0, bfgs: bool) -> _Iterate:
    """The iterate at a solved ``(motors0, state0)``."""
    value, gradient, model, ds_da = _evaluate(objective, mech, geom, motors0, state0)
    start_hessian = jnp.eye(motors0.shape[0]) if bfgs else model
    return _Iterate(motors0, state0, value, gradient, start_hessian, ds_da, jnp.asarray(1e-6), jnp.asarray(mech.evaluation.max_step), jnp.asarray(0), jnp.asarray(False))


def _step(mech: Mechanism, geom: Geometry, objective, bfgs: bool, it: _Iterate) -> _Iterate:
    """One damped quasi-Newton step with its trial forward solve (module docstring)."""
    size = it.motors.shape[0]
    max_step = mech.evaluation.max_step
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


def _finished(it: _Iterate, iterations: int) -> Bool[Array, "..."]:
    """Whether an iterate stops: converged, stalled or at the iteration cap."""
    return it.done | (it.iteration >= iterations)


def minimise(mech: Mechanism, geom: Geometry, objective, motors0, state0, iterations: int, bfgs: bool) -> Sample:
    """Minimise ``objective`` over motors from a solved ``(motors0, state0)`` (see module doc)."""
    it0 = _start(mech, geom, objective, motors0, state0, bfgs)
    final = jax.lax.while_loop(lambda it: ~_finished(it, iterations), lambda it: _step(mech, geom, objective, bfgs, it), it0)
    return Sample(final.motors, final.state, final.value, final.iteration)


def _where(mask: Bool[Array, " W"], new, old):
    """``new`` where ``mask`` else ``old``, leaf by leaf, ``mask`` on the leading axis."""
    return jax.tree_util.tree_map(lambda n, o: jnp.where(mask.reshape(mask.shape + (1,) * (n.ndim - 1)), n, o), new, old)


def minimise_queue(
    mech: Mechanism,
    problem,
    lanes,
    motors0: Float[Array, "L M"],
    state0: Float[Array, "L S"],
    iterations: int,
    bfgs: bool,
    width: int,
) -> Sample:
    """:func:`minimise` of ``L`` independent lanes through ``width`` slots (module docstring).

    ``problem(lane) -> (geom, objective)`` builds one lane's problem from its leaf-wise
    slice of ``lanes`` (a pytree with leading axis ``L``). Each lane takes the steps it
    takes under ``vmap(minimise)``; a slot whose lane has finished takes the next waiting
    lane, so the batch that a step costs is ``width`` wide, not ``L``. Returns the
    ``L`` samples in lane order.
    """
    count = motors0.shape[0]
    width = min(width, count)
    take = lambda tree, index: jax.tree_util.tree_map(lambda a: a[index], tree)  # noqa: E731

    def start(lane, motors, state):
        geom, objective = problem(lane)
        return _start(mech, geom, objective, motors, state, bfgs)

    def step(lane, it):
        geom, objective = problem(lane)
        return _step(mech, geom, objective, bfgs, it)

    waiting = jax.vmap(start)(lanes, motors0, state0)
    out = Sample(waiting.motors, waiting.state, waiting.value, waiting.iteration)
    if iterations < 1:
        return out
    first = jnp.arange(width)

    def body(carry):
        slots, slot_lanes, owner, upcoming, out = carry
        slots = jax.vmap(step)(slot_lanes, slots)
        finished = (owner >= 0) & _finished(slots, iterations)
        index = jnp.where(finished, owner, count)
        result = Sample(slots.motors, slots.state, slots.value, slots.iteration)
        out = jax.tree_util.tree_map(lambda o, r: o.at[index].set(r, mode="drop"), out, result)
        free = finished | (owner < 0)
        incoming = upcoming + jnp.cumsum(free) - 1
        fill = free & (incoming < count)
        source = jnp.minimum(incoming, count - 1)
        slots = _where(fill, take(waiting, source), slots)
        slot_lanes = _where(fill, take(lanes, source), slot_lanes)
        owner = jnp.where(fill, incoming, jnp.where(free, -1, owner))
        return slots, slot_lanes, owner, upcoming + jnp.sum(free), out

    carry = (take(waiting, first), take(lanes, first), first, jnp.asarray(width), out)
    carry = jax.lax.while_loop(lambda c: jnp.any(c[2] >= 0), body, carry)
    return carry[4]


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
