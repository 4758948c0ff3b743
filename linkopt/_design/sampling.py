"""IK samples (paper eq. 4) and adversarial samples (eq. 5) for one design.

Both minimise a function of the motor values ``a`` whose state ``s(a)`` is the forward
kinematics solution, with exact gradients through the implicit function theorem:
``ds/da = -(JᵀJ)⁻¹ Jᵀ ∂C_FK/∂a`` (including the singularity terms, where the paper used
finite differences). Everything is homogenised.

The minimiser (:func:`minimise`) is the damped trust-region quasi-Newton method of
:mod:`linkopt._engine.solvers.quasi_newton` on the 1-3 motor values, with the
Gauss–Newton matrix of the reach residual for IK samples and a BFGS estimate for
adversarial samples (whose ``f_sing`` has no usable exact Hessian). A point is a
forward solve (:class:`Motors`): every trial forward solve starts from the linear
prediction ``s + (ds/da) δ``, and a trial is rejected when the solved state departs
from that prediction by more than half of ``(ds/da) δ``: that is how a step that
crossed a forward singularity onto another assembly branch shows up. The paper's BFGS
with an unguarded step could cross (its Fig. 4); this guard is our addition.

Motor limits (``[[motors]]`` ``min``/``max``) make both searches minimisations over
the box of allowed motor values by projected Newton steps
(:mod:`linkopt._design.motor_box`); without limits none of it is traced.

The step bound is a trust radius from the file's ``max_step`` (the solver's module
docstring): samples travel far from the rest pose, and a fixed small step would spend
the iteration cap getting there.

Under ``vmap`` a ``while_loop`` steps every lane until the last one stops, so a batch
costs its slowest lane's iterations times its width. :func:`minimise_queue` runs ``L``
lanes through ``width`` slots instead, each lane's IK minimisation and then its
adversarial one from the IK result: a slot moves on to its lane's second phase, or to
the next waiting lane, as soon as a phase stops, and each phase takes the steps it takes
in :func:`minimise` (up to the rounding of a flat batch against nested ``vmap``).
Lanes' iteration counts are spread (an unreachable target runs to the cap), which is
what the queue saves.

Starting a minimisation is a step of length zero (the solver state's ``fresh``), and
both phases share the step, choosing objective and Hessian model per slot, so the
compiled loop holds the expensive evaluation (trial solve, ``ds/da``, ``f_sing`` and
its gradient) once rather than four times (IK start and step, adversarial start and
step), which keeps the program small to compile and load
(``benchmarks/bench_evaluation.py``).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass

import jax
import jax.numpy as jnp
from jaxtyping import Array, Bool, Float, Int

from .._engine import banded, dense
from .._engine.constraints import motor_residual
from .._engine.geometry import Geometry
from .._engine.jacobian import state_jacobian
from .._engine.kinematics import solve_single
from .._engine.model import Mechanism
from .._engine.singularity import sigma_min_pair, sigmas_of, stacked_jacobians
from .._engine.solvers.driver import run, stopped
from .._engine.solvers.quasi_newton import QNState, QuasiNewton, unevaluated
from .motor_box import held, into_box, motor_box, projected

BRANCH_TOL = 0.5
#: Iteration cap of a trial forward solve: from the linear prediction, a step of at
#: most ``quasi_newton.RADIUS_GROWTH · max_step`` converges in 2-4 LM iterations; one
#: that needs more is rejected, since under ``vmap`` a lane that ran on to a longer cap
#: would hold up every other sample.
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
class _Point:
    """What the solver carries of a solved point besides the motors."""

    state: Float[Array, " S"]
    ds_da: Float[Array, "S M"]
    f_sing: Float[Array, ""]


def state_motor_jacobian(
    mech: Mechanism, geom: Geometry, motors, state
) -> Float[Array, "S M"]:
    """``ds/da`` at a solved state (eq. 2, least-squares form for tall Jacobians); on
    the band where the solves take it (:func:`linkopt._engine.banded.motor_tangent`)."""
    if banded.serves(mech):
        return banded.motor_tangent(mech, geom, motors, state)
    jac_s = state_jacobian(mech, geom, "fk", state)
    return -dense.solve_spd(
        jac_s.T @ jac_s, _motor_rows_product(mech, geom, motors, state, jac_s)
    )


def _motor_rows_product(mech: Mechanism, geom: Geometry, motors, state, jac_s):
    """``Jᵀ ∂C_FK/∂a`` from the motor rows alone: ``∂C_FK/∂a`` is zero in the
    passive rows (they do not read the motors), so only the last ``M`` rows of ``J``
    and the motor rows' own derivative (forward mode through them) take part."""
    jac_m = jax.jacfwd(lambda a: motor_residual(mech, geom, a, state))(motors)
    return jac_s[jac_s.shape[0] - mech.num_motors :].T @ jac_m


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
    gradient comes from the stacked Jacobians' pullback. Where the solves take the
    band (:func:`linkopt._engine.banded.serves`) no dense Jacobian is built: σ_min,
    its gradient and ``ds/da`` come from the banded factor, linear in the bodies."""
    if banded.serves(mech):
        return _banded_point(objective, mech, geom, motors, state)
    jac, pullback = jax.vjp(lambda s: stacked_jacobians(mech, geom, s), state)
    f_sing, d_jac = jax.value_and_grad(lambda j: jnp.sum(1.0 / sigmas_of(j)))(jac)
    (d_f_sing,) = pullback(d_jac)
    jac_s = jac[0]
    projected = _motor_rows_product(mech, geom, motors, state, jac_s)
    ds_da = -dense.solve_spd(jac_s.T @ jac_s, projected)
    value, gradient, model = objective(motors, state, ds_da, f_sing, d_f_sing)
    return value, gradient, model, ds_da, f_sing


def _banded_point(objective: Objective, mech: Mechanism, geom: Geometry, motors, state):
    """:func:`evaluate_point` on the band (:mod:`linkopt._engine.banded_sigma`)."""
    f_sing, d_f_sing = jax.value_and_grad(
        lambda s: jnp.sum(1.0 / sigma_min_pair(mech, geom, s))
    )(state)
    ds_da = banded.motor_tangent(mech, geom, motors, state)
    value, gradient, model = objective(motors, state, ds_da, f_sing, d_f_sing)
    return value, gradient, model, ds_da, f_sing


def _start(motors0: Float[Array, " M"], state0: Float[Array, " S"]) -> tuple:
    """``(motors0, point)`` at a solved start point, the objective not computed yet."""
    ds_da = jnp.zeros(state0.shape + motors0.shape)
    return motors0, _Point(state0, ds_da, jnp.zeros(()))


@dataclass(frozen=True)
class _Box:
    """The motor limits as the solver's bounds (:mod:`linkopt._design.motor_box`)."""

    box: tuple

    def hold(self, x, system, gradient):
        return held(self.box, x, system, gradient)

    def clip(self, x, delta):
        return into_box(self.box, x, delta)

    def spent(self, x, gradient):
        return projected(self.box, x, gradient)


@dataclass(frozen=True)
class Motors:
    """The quasi-Newton problem over motor values: a point is a forward solve."""

    mech: Mechanism
    geom: Geometry
    objective: Objective

    def trial(self, it: QNState, delta, fresh):
        """The forward solve at ``x + δ`` from its linear prediction ``s + (ds/da) δ``,
        and whether it converged on the iterate's branch (module docstring)."""
        point = it.point
        predicted = jnp.where(fresh, 0.0, point.ds_da @ delta)
        trial = solve_single(
            self.mech,
            "fk",
            self.geom,
            it.x + delta,
            point.state + predicted,
            TRIAL_ITERATIONS,
        )
        state = jnp.where(fresh, point.state, trial.state)
        departure = jnp.sqrt(jnp.sum((trial.state - point.state - predicted) ** 2))
        on_branch = departure <= BRANCH_TOL * jnp.sqrt(predicted @ predicted) + 1e-10
        return state, trial.converged & on_branch

    def evaluate(self, motors, state):
        value, gradient, model, ds_da, f_sing = evaluate_point(
            self.objective, self.mech, self.geom, motors, state
        )
        return value, gradient, model, _Point(state, ds_da, f_sing)


def _solver(mech: Mechanism, geom: Geometry, objective: Objective, bfgs) -> QuasiNewton:
    box = motor_box(mech)
    return QuasiNewton(
        Motors(mech, geom, objective),
        mech.evaluation.max_step,
        bfgs,
        None if box is None else _Box(box),
    )


def _sample(it: QNState) -> Sample:
    return Sample(it.x, it.point.state, it.value, it.point.f_sing, it.iteration)


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
    solver = _solver(mech, geom, objective, bfgs)
    final, _ = run(solver, _start(motors0, state0), iterations)
    return _sample(final)


def _where(mask: Bool[Array, " W"], new, old):
    """``new`` where ``mask`` else ``old``, leaf by leaf, ``mask`` on the leading
    axis."""
    return jax.tree_util.tree_map(
        lambda n, o: jnp.where(mask.reshape(mask.shape + (1,) * (n.ndim - 1)), n, o),
        new,
        old,
    )


def _store(out: Sample, lane: Int[Array, " W"], it: QNState) -> Sample:
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

    slots: QNState  # each slot's solver state
    second: Bool[Array, " W"]  # the slot's lane is in phase two
    anchor: Float[Array, "W M"]  # phase one's final motors, for phase two
    lanes: object  # the slot's lane's slice of ``lanes``
    owner: Int[Array, " W"]  # the lane the slot works on, -1 when idle
    upcoming: Int[Array, ""]  # the first lane still waiting for a slot
    outs: tuple[Sample, Sample]  # both phases' samples, in lane order


def _start_queue(blank: QNState, lanes, motors0, width: int) -> _Queue:
    """The first ``width`` lanes in the slots, each about to start phase one."""
    first = jnp.arange(width)
    out = _sample(blank)
    no = jnp.zeros(width, bool)
    return _Queue(
        _take(blank, first),
        no,
        motors0[first],
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
    anchor = jnp.where(first_done[:, None], queue.slots.x, queue.anchor)
    queue = dataclasses.replace(
        queue,
        slots=dataclasses.replace(queue.slots, fresh=first_done),
        anchor=anchor,
        second=queue.second | first_done,
        outs=outs,
    )
    return queue, second_done


def _refill(
    queue: _Queue, free: Bool[Array, " W"], blank: QNState, lanes, count: int
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
    # each lane's start, unevaluated
    blank = jax.vmap(lambda m, s: unevaluated(*_start(m, s)))(motors0, state0)

    def step(lane, second, anchor, it):
        geom, objective = problem(lane, second, anchor)
        solver = _solver(mech, geom, objective, second)
        it = solver.step(it)
        return it, stopped(solver, it, caps[second.astype(int)])

    def body(queue: _Queue) -> _Queue:
        slots, stops = jax.vmap(step)(
            queue.lanes, queue.second, queue.anchor, queue.slots
        )
        finished = (queue.owner >= 0) & stops
        queue, second_done = _end_phases(
            dataclasses.replace(queue, slots=slots), finished, count
        )
        free = second_done | (queue.owner < 0)
        return _refill(queue, free, blank, lanes, count)

    queue = _start_queue(blank, lanes, motors0, width)
    queue = jax.lax.while_loop(lambda q: jnp.any(q.owner >= 0), body, queue)
    return queue.outs
