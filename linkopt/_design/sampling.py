"""IK samples (paper eq. 4) and adversarial samples (eq. 5) for one design.

Both minimise a function of the motor values ``a`` whose state ``s(a)`` is the forward
kinematics solution, with exact gradients through the implicit function theorem:
``ds/da = -(JᵀJ)⁻¹ Jᵀ ∂C_FK/∂a`` (including the singularity terms, where the paper used
finite differences). Everything is homogenised.

The minimiser (:func:`minimise`) is a damped quasi-Newton method on the 1-3 motor
values: step ``δ = -(H + λI)⁻¹ g`` with ``‖δ‖ ≤ r``, accepted on an Armijo decrease,
else ``λ`` grows. ``H`` is the Gauss–Newton matrix of the reach residual for IK samples
and a BFGS estimate for adversarial samples (whose ``f_sing`` has no usable exact
Hessian). Every trial forward solve starts from the linear prediction ``s + (ds/da) δ``,
and a trial is rejected when the solved state departs from that prediction by more than
half of ``(ds/da) δ``: that is how a step that crossed a forward singularity onto
another assembly branch shows up. The paper's BFGS with an unguarded step could cross
(its Fig. 4); this guard is our addition.

Motor limits (``[[motors]]`` ``min``/``max``) make both searches minimisations over
the box of allowed motor values by projected Newton steps
(:mod:`linkopt._design.motor_box`); without limits none of it is traced.

The step bound ``r`` is a trust radius: it starts at the file's ``max_step``, doubles
after an accepted step that it had to shorten (up to ``RADIUS_GROWTH · max_step``) and
halves after a rejected one (down to ``max_step``): samples travel far from the rest
pose, and a fixed small step would spend the iteration cap getting there. Iteration
stops when the gradient is below ``GRADIENT_TOL``,
or when an accepted step that the radius did not shorten lowered the value by at most
``VALUE_RTOL`` of it (a converged quasi-Newton step: targets out of reach never get a
zero gradient), or at the iteration cap.

Under ``vmap`` a ``while_loop`` steps every lane until the last one stops, so a batch
costs its slowest lane's iterations times its width. :func:`minimise_queue` runs ``L``
lanes through ``width`` slots instead, each lane's IK minimisation and then its
adversarial one from the IK result: a slot moves on to its lane's second phase, or to
the next waiting lane, as soon as a phase stops, and each phase takes the steps it takes
in :func:`minimise` (up to the rounding of a flat batch against nested ``vmap``).
Lanes' iteration counts are spread (an unreachable target runs to the cap), which is
what the queue saves.

Starting a minimisation is a :func:`_step` of length zero (``fresh``), and both phases
share the step, choosing objective and Hessian model per slot, so the compiled loop
holds the expensive evaluation (trial solve, ``ds/da``, ``f_sing`` and its gradient)
once rather than four times (IK start and step, adversarial start and step), which
keeps the program small to compile and load (``benchmarks/bench_evaluation.py``).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass

import jax
import jax.numpy as jnp
from jaxtyping import Array, Bool, Float, Int

from .._engine import dense, dense_lu
from .._engine.constraints import (
    fk_residual,
)
from .._engine.geometry import Geometry
from .._engine.jacobian import state_jacobian
from .._engine.kinematics import solve_single
from .._engine.model import Mechanism
from .._engine.singularity import sigmas_of, stacked_jacobians
from .motor_box import held, into_box, motor_box, projected

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


@jax.tree_util.register_dataclass
@dataclass(frozen=True)
class Sample:
    motors: Float[Array, " M"]  # homogenised
    state: Float[Array, " S"]
    value: Float[Array, ""]
    f_sing: Float[Array, ""]  # f_sing at ``state``
    iterations: Int[Array, ""]


@jax.tree_util.register_dataclass
@dataclass(frozen=True)
class _Iterate:
    motors: Float[Array, " M"]
    state: Float[Array, " S"]
    value: Float[Array, ""]
    gradient: Float[Array, " M"]
    hessian: Float[Array, "M M"]
    ds_da: Float[Array, "S M"]
    f_sing: Float[Array, ""]
    damping: Float[Array, ""]
    radius: Float[Array, ""]
    iteration: Int[Array, ""]
    done: Bool[Array, ""]


def state_motor_jacobian(
    mech: Mechanism, geom: Geometry, motors, state
) -> Float[Array, "S M"]:
    """``ds/da`` at a solved state (eq. 2, least-squares form for tall Jacobians)."""
    jac_s = state_jacobian(mech, geom, "fk", state)
    jac_a = jax.jacfwd(lambda a: fk_residual(mech, geom, a, state))(motors)
    return -dense.solve_spd(jac_s.T @ jac_s, jac_s.T @ jac_a)


#: An objective maps ``(motors, state, ds/da, f_sing, ∂f_sing/∂s)`` at a solved state to
#: ``(value, gradient in motors, Gauss–Newton matrix)`` (zeros where it has none). The
#: caller computes ``f_sing`` and its gradient once per point, since every objective
#: here uses them and they are most of a step's cost.
Objective = Callable[..., tuple]


def evaluate_point(
    objective: Objective, mech: Mechanism, geom: Geometry, motors, state
):
    """The objective at a solved point, with ``ds/da`` and ``f_sing``. The forward
    Jacobian is built once, for σ_min and for ``ds/da`` (eq. 2): ``f_sing``'s
    gradient comes from the stacked Jacobians' pullback."""
    jac, pullback = jax.vjp(lambda s: stacked_jacobians(mech, geom, s), state)
    f_sing, d_jac = jax.value_and_grad(lambda j: jnp.sum(1.0 / sigmas_of(j)))(jac)
    (d_f_sing,) = pullback(d_jac)
    jac_s = jac[0]
    jac_a = jax.jacfwd(lambda a: fk_residual(mech, geom, a, state))(motors)
    ds_da = -dense.solve_spd(jac_s.T @ jac_s, jac_s.T @ jac_a)
    value, gradient, model = objective(motors, state, ds_da, f_sing, d_f_sing)
    return value, gradient, model, ds_da, f_sing


def _unevaluated(motors0: Float[Array, " M"], state0: Float[Array, " S"]) -> _Iterate:
    """An iterate at a start point whose objective is not computed yet: the next
    :func:`_step` with ``fresh`` evaluates it."""
    size, zero = motors0.shape[0], jnp.zeros(())
    return _Iterate(
        motors0,
        state0,
        zero,
        jnp.zeros(size),
        jnp.eye(size),
        jnp.zeros(state0.shape + (size,)),
        zero,
        zero,
        zero,
        jnp.asarray(0),
        jnp.asarray(False),
    )


@jax.tree_util.register_dataclass
@dataclass(frozen=True)
class _Trial:
    """A trial step and its forward solve (module docstring)."""

    delta: Float[Array, " M"]  # the step in motors, zero when fresh
    shortened: Bool[Array, ""]  # the trust radius cut it
    state: Float[Array, " S"]  # the solved state (the iterate's own when fresh)
    converged: Bool[Array, ""]
    on_branch: Bool[Array, ""]  # the solve stayed near the linear prediction


def _trial(mech: Mechanism, geom: Geometry, it: _Iterate, fresh) -> _Trial:
    """The damped quasi-Newton step within the trust radius, and the forward solve from
    its linear prediction ``s + (ds/da) δ``."""
    size = it.motors.shape[0]
    system = it.hessian + it.damping * jnp.eye(size)
    gradient = it.gradient
    box = motor_box(mech)
    if box is not None:  # static: without limits the step is as it was
        system, gradient = held(box, it.motors, system, gradient)
    delta = -dense_lu.solve(system, gradient)  # LU, as jnp.linalg.solve
    norm = jnp.sqrt(delta @ delta)
    shortened = norm > it.radius
    delta = jnp.where(
        fresh, 0.0, delta * jnp.minimum(1.0, it.radius / jnp.maximum(norm, 1e-300))
    )
    if box is not None:
        delta = into_box(box, it.motors, delta)
    predicted = jnp.where(fresh, 0.0, it.ds_da @ delta)
    trial = solve_single(
        mech, "fk", geom, it.motors + delta, it.state + predicted, TRIAL_ITERATIONS
    )
    state = jnp.where(fresh, it.state, trial.state)
    departure = jnp.sqrt(jnp.sum((trial.state - it.state - predicted) ** 2))
    on_branch = departure <= BRANCH_TOL * jnp.sqrt(predicted @ predicted) + 1e-10
    return _Trial(delta, shortened, state, trial.converged, on_branch)


def _bfgs(it: _Iterate, delta, gradient) -> Float[Array, "M M"]:
    """The BFGS update of the iterate's Hessian estimate, kept where the curvature is
    not positive."""
    y = gradient - it.gradient
    curvature = y @ delta
    hb = it.hessian @ delta
    updated = (
        it.hessian
        - jnp.outer(hb, hb) / (delta @ hb)
        + jnp.outer(y, y) / jnp.where(curvature > 0, curvature, 1.0)
    )
    return jnp.where(curvature > 1e-12, updated, it.hessian)


def _trust(it: _Iterate, accept, shortened, max_step) -> tuple:
    """The next damping and trust radius (module docstring)."""
    damping = jnp.where(
        accept, jnp.maximum(it.damping / 3.0, 1e-9), it.damping * 4.0 + 1e-6
    )
    radius = jnp.where(
        accept,
        jnp.where(
            shortened, jnp.minimum(2.0 * it.radius, RADIUS_GROWTH * max_step), it.radius
        ),
        jnp.maximum(it.radius / 2.0, max_step),
    )
    return damping, radius


def _step(
    mech: Mechanism,
    geom: Geometry,
    objective: Objective,
    bfgs,
    it: _Iterate,
    fresh=False,
) -> _Iterate:
    """One damped quasi-Newton step with its trial forward solve (module docstring).

    With ``fresh`` the step has length zero and is accepted: the iterate becomes the
    start of a minimisation at its (solved) point, with the Gauss–Newton matrix (or the
    identity with ``bfgs``), the initial damping and radius, and iteration 0. Starting
    and stepping are one function so that a compiled loop holds the expensive
    evaluation once. ``bfgs`` and ``fresh`` may be traced booleans.
    """
    fresh = jnp.asarray(fresh)
    max_step = mech.evaluation.max_step
    trial = _trial(mech, geom, it, fresh)
    delta, state = trial.delta, trial.state
    value, gradient, model, ds_da, f_sing = evaluate_point(
        objective, mech, geom, it.motors + delta, state
    )
    decrease = value <= it.value + ARMIJO * (it.gradient @ delta)
    accept = fresh | (
        trial.converged & trial.on_branch & decrease & jnp.isfinite(value)
    )
    quasi_newton = _bfgs(it, delta, gradient)
    eye = jnp.eye(it.motors.shape[0])
    model = jnp.where(bfgs, jnp.where(fresh, eye, quasi_newton), model)

    def pick(new, old):
        return jnp.where(accept, new, old)

    damping, radius = _trust(it, accept, trial.shortened, max_step)
    kept = pick(gradient, it.gradient)
    box = motor_box(mech)
    if box is not None:  # a gradient that pushes against a limit is spent
        kept = projected(box, pick(it.motors + delta, it.motors), kept)
    small = jnp.max(jnp.abs(kept)) < GRADIENT_TOL
    stalled = (
        accept & ~trial.shortened & (it.value - value <= VALUE_RTOL * jnp.abs(value))
    )
    return _Iterate(
        motors=pick(it.motors + delta, it.motors),
        state=pick(state, it.state),
        value=pick(value, it.value),
        gradient=pick(gradient, it.gradient),
        hessian=pick(model, it.hessian),
        ds_da=pick(ds_da, it.ds_da),
        f_sing=pick(f_sing, it.f_sing),
        damping=jnp.where(fresh, 1e-6, damping),
        radius=jnp.where(fresh, max_step, radius),
        iteration=jnp.where(fresh, 0, it.iteration + 1),
        done=~fresh & (small | stalled | (damping > MAX_DAMPING)),
    )


def _finished(it: _Iterate, iterations) -> Bool[Array, ...]:
    """Whether an iterate stops: converged, stalled or at the iteration cap."""
    return it.done | (it.iteration >= iterations)


def _sample(it: _Iterate) -> Sample:
    return Sample(it.motors, it.state, it.value, it.f_sing, it.iteration)


def minimise(
    mech: Mechanism,
    geom: Geometry,
    objective: Objective,
    motors0,
    state0,
    iterations: int,
    bfgs: bool,
) -> Sample:
    """Minimise ``objective`` over motors from a solved ``(motors0, state0)`` (see
    module doc)."""
    it0 = _step(mech, geom, objective, bfgs, _unevaluated(motors0, state0), fresh=True)
    final = jax.lax.while_loop(
        lambda it: ~_finished(it, iterations),
        lambda it: _step(mech, geom, objective, bfgs, it),
        it0,
    )
    return _sample(final)


def _where(mask: Bool[Array, " W"], new, old):
    """``new`` where ``mask`` else ``old``, leaf by leaf, ``mask`` on the leading
    axis."""
    return jax.tree_util.tree_map(
        lambda n, o: jnp.where(mask.reshape(mask.shape + (1,) * (n.ndim - 1)), n, o),
        new,
        old,
    )


def _store(out: Sample, lane: Int[Array, " W"], it: _Iterate) -> Sample:
    """``out`` with row ``lane[w]`` set to slot ``w``'s sample; lane ``L`` is
    dropped."""
    return jax.tree_util.tree_map(
        lambda o, r: o.at[lane].set(r, mode="drop"), out, _sample(it)
    )


def _take(tree, index):
    """Rows ``index`` of every leaf of ``tree``."""
    return jax.tree_util.tree_map(lambda a: a[index], tree)


@jax.tree_util.register_dataclass
@dataclass(frozen=True)
class _Queue:
    """The loop state of :func:`minimise_queue`, one row per slot (``W`` slots)."""

    slots: _Iterate  # each slot's iterate
    second: Bool[Array, " W"]  # the slot's lane is in phase two
    anchor: Float[Array, "W M"]  # phase one's final motors, for phase two
    fresh: Bool[Array, " W"]  # the slot's next step starts a minimisation
    lanes: object  # the slot's lane's slice of ``lanes``
    owner: Int[Array, " W"]  # the lane the slot works on, -1 when idle
    upcoming: Int[Array, ""]  # the first lane still waiting for a slot
    outs: tuple[Sample, Sample]  # both phases' samples, in lane order


def _start_queue(blank: _Iterate, lanes, motors0, width: int) -> _Queue:
    """The first ``width`` lanes in the slots, each about to start phase one."""
    first = jnp.arange(width)
    out = _sample(blank)
    no = jnp.zeros(width, bool)
    return _Queue(
        _take(blank, first),
        no,
        motors0[first],
        ~no,
        _take(lanes, first),
        first,
        jnp.asarray(width),
        (out, out),
    )


def _end_phases(queue: _Queue, finished: Bool[Array, " W"], count: int):
    """Store the samples of the phases that finished; a slot whose lane finished phase
    one starts phase two where phase one ended. Also returns where phase two
    finished."""
    first_done, second_done = finished & ~queue.second, finished & queue.second
    outs = (
        _store(queue.outs[0], jnp.where(first_done, queue.owner, count), queue.slots),
        _store(queue.outs[1], jnp.where(second_done, queue.owner, count), queue.slots),
    )
    anchor = jnp.where(first_done[:, None], queue.slots.motors, queue.anchor)
    queue = dataclasses.replace(
        queue,
        anchor=anchor,
        second=queue.second | first_done,
        fresh=first_done,
        outs=outs,
    )
    return queue, second_done


def _refill(
    queue: _Queue, free: Bool[Array, " W"], blank: _Iterate, lanes, count: int
) -> _Queue:
    """The ``free`` slots take the next waiting lanes, in order, while any wait; the
    others of them fall idle."""
    incoming = queue.upcoming + jnp.cumsum(free) - 1
    fill = free & (incoming < count)
    source = jnp.minimum(incoming, count - 1)
    slots = _where(fill, _take(blank, source), queue.slots)
    slot_lanes = _where(fill, _take(lanes, source), queue.lanes)
    return _Queue(
        slots,
        queue.second & ~fill,
        queue.anchor,
        queue.fresh | fill,
        slot_lanes,
        jnp.where(fill, incoming, jnp.where(free, -1, queue.owner)),
        queue.upcoming + jnp.sum(free),
        queue.outs,
    )


def minimise_queue(
    mech: Mechanism,
    problem: Callable,
    lanes,
    motors0: Float[Array, "L M"],
    state0: Float[Array, "L S"],
    iterations: tuple[int, int],
    width: int,
) -> tuple[Sample, Sample]:
    """Two chained minimisations of each of ``L`` lanes through ``width`` slots.

    Each lane first minimises from ``(motors0, state0)`` (phase one, Gauss–Newton model,
    at most ``iterations[0]`` steps), then from phase one's result (phase two, BFGS, at
    most ``iterations[1]`` steps).
    ``problem(lane, second, anchor) -> (geom, objective)`` builds a lane's problem from
    its leaf-wise slice of ``lanes`` (a pytree with leading axis ``L``), ``second``
    (traced: phase two) and ``anchor`` (phase one's motors, for phase two). Each phase
    takes the steps it takes under ``vmap(minimise)``; a slot whose lane has finished
    phase one starts phase two at once, and one that has finished phase two takes the
    next waiting lane, so a step costs a batch ``width`` wide, not ``L``. Returns both
    phases' ``L`` samples in lane order.
    """
    count = motors0.shape[0]
    width = min(width, count)
    caps = jnp.asarray(iterations)
    blank = jax.vmap(_unevaluated)(motors0, state0)  # each lane's start, unevaluated

    def step(lane, second, anchor, fresh, it):
        geom, objective = problem(lane, second, anchor)
        return _step(mech, geom, objective, second, it, fresh)

    def body(queue: _Queue) -> _Queue:
        slots = jax.vmap(step)(
            queue.lanes, queue.second, queue.anchor, queue.fresh, queue.slots
        )
        finished = (queue.owner >= 0) & _finished(slots, caps[queue.second.astype(int)])
        queue, second_done = _end_phases(
            dataclasses.replace(queue, slots=slots), finished, count
        )
        free = second_done | (queue.owner < 0)
        return _refill(queue, free, blank, lanes, count)

    queue = _start_queue(blank, lanes, motors0, width)
    queue = jax.lax.while_loop(lambda q: jnp.any(q.owner >= 0), body, queue)
    return queue.outs
