"""Continuation: a solved state carried along a straight line of motor or output
values by predictor-corrector steps (:func:`walk`;
:func:`linkopt._engine.kinematics.continue_to` wraps it as a
:class:`~linkopt._engine.kinematics.Solution`).

Each step predicts the state at its values to first order (``s + ds/dv Δv``,
:func:`predict`) and corrects it by Levenberg–Marquardt (:func:`corrector`); it is
accepted when the corrector converges near the prediction (within
``PREDICTION_RATIO`` of the predicted move), which tells the start's assembly branch
from another one, and then doubles; it halves otherwise, and the walk is stuck below
``MIN_STEP``.

On the dense path the walk is **one loop of linearisations** (:func:`_dense_walk`):
every pass solves one damped system and linearises once at the point it gives, either
a step's prediction (the last accepted linearisation's normal equations, with the
motor or output rows moved by the values' change: :func:`predict_from`) or the
corrector's next Levenberg–Marquardt trial (:func:`.solvers.lm.update`). Nested (a
walk loop around the corrector's own loop, as on the band), the program held the
linearisation three times (the walk's start, the corrector's first point, its steps)
and a vmapped chunk ran each step's corrector until its slowest lane was done; here a
lane that has finished its corrector starts its next step while others still correct,
and the program holds the linearisation twice (the walk's start, the loop). Each lane
does the same arithmetic as the nested loops, in the same order.

On the band (:mod:`.banded`, long linkages) the walk keeps the nested loops
(:func:`_advance`): its prediction linearises afresh (:func:`.banded.predict`), and is
followed by chord steps with the rows and factor it was made with
(:mod:`.solvers.chord`) before the LM corrector. A long linkage's lever arm grows the
prediction's error, and with it the LM iterations, each a new band assembly and
factor; a chord step costs a residual and two scans. ``benchmarks/bench_bodies.py``'s
rows (SPAN 0.05 rad, 16 rows, CPU per solve, against the walk without them in one
process, load 6-7): ladder of 300 bodies 27.9 -> 7.1 ms (LM iterations per solve 6.06
-> 0), lazy tongs of 100 bodies 5.3 -> 1.3 ms (8.06 -> 0). On the dense path (five-bar,
Jansen leg, ±0.3 rad from rest) the same steps cut the LM iterations (4.1 -> 1.0 per
solve) but not the time (a chord step there cost about what the LM iteration it saved
did), so the dense walk has none. ``Solution.iterations`` counts LM iterations, not
chord steps.
"""

from __future__ import annotations

from dataclasses import dataclass

import jax
import jax.numpy as jnp
from jaxtyping import Array, Bool, Float, Int

from . import banded, dense, jacobian
from .constraints import bk_residual, fk_residual
from .geometry import Geometry
from .model import Mechanism
from .solvers import chord, lm

_RESIDUALS = {"fk": fk_residual, "bk": bk_residual}

#: Largest change of any motor or output in one continuation step (homogenised: rad, or
#: reference lengths). Small enough that the first-order prediction tells the rest
#: branch from another assembly of the same values.
MAX_STEP = 0.2
#: Smallest step, same units; a continuation that must shrink below it stops there.
MIN_STEP = 1e-6
#: A step is accepted when the corrector moves the predicted state by at most this
#: fraction of the predicted move (plus ``PREDICTION_SLACK``): on the branch the
#: correction shrinks with the step squared, a jump to another assembly does not.
PREDICTION_RATIO = 0.5
PREDICTION_SLACK = 1e-7
#: Cap on continuation steps (accepted and rejected) per solve.
MAX_STEPS = 400
#: Damping of the prediction's solve (``JᵀJ`` is singular only at a singularity).
PREDICTION_DAMPING = 1e-12


def corrector(
    mech: Mechanism,
    kind: str,
    geom: Geometry,
    values,
    start,
    max_iterations: int | None = None,
    with_tail: bool = False,
) -> lm.LMResult:
    """LM on ``C(values, s)`` from ``start`` with the file's ``[solver]`` settings
    (``with_tail``: the result's linearisation holds the motor or output rows'
    Jacobian too, for :func:`predict_from`)."""
    settings = mech.solver
    linearise = (
        jacobian.normal_equations_tail if with_tail else jacobian.normal_equations
    )
    method = lm.NormalEquations(
        lambda s: _RESIDUALS[kind](mech, geom, values, s),
        lambda s: linearise(mech, geom, kind, values, s),
    )
    if banded.serves(mech):
        method = banded.Banded(mech, geom, kind, values)
    return lm.solve(
        method,
        start,
        tolerance=settings.tolerance,
        max_iterations=max_iterations or settings.max_iterations,
        initial_damping=settings.initial_damping,
    )


def predict(mech: Mechanism, kind: str, geom: Geometry, values, state):
    """First-order prediction of the state solved at ``values``, from a state solved
    at nearby values: ``s + ds = s - (JᵀJ)⁻¹ Jᵀ C(values, s)``.

    The residual is affine in the values (unit slope on the motor or output rows) and
    ``C`` vanishes at the old values, so ``Jᵀ C(values, s) = Jᵀ ∂C/∂v Δv``: this is the
    tangent ``ds/dv Δv`` of the implicit function theorem (least squares where rows
    are redundant), built from the LM solver's own normal equations."""
    if banded.serves(mech):
        return banded.predict(mech, kind, geom, values, state)[0]
    _, hessian, gradient = jacobian.normal_equations(mech, geom, kind, values, state)
    return state - dense.damped_solve(hessian, PREDICTION_DAMPING, gradient)


def _moved_gradient(known, change):
    """``Jᵀ C`` of ``known = (C, (JᵀJ, JᵀC, J_tail))`` with the values moved by
    ``change``: only the motor or output rows change with the values, each by
    ``-change`` (unit slope; a state solved at the old values leaves a wrapped angle
    row far from ``±π``), so it is ``JᵀC - J_tailᵀ change``."""
    _, (_, gradient, tail) = known
    return gradient - jnp.sum(tail * change[:, None], axis=0)


def predict_from(state, known, change):
    """:func:`predict` (dense) from ``known = (C, (JᵀJ, JᵀC, J_tail))`` at ``state``,
    the last corrector's linearisation (:func:`.jacobian.normal_equations_tail`), for
    values moved by ``change`` (homogenised): no linearisation per step; equal to
    :func:`predict` to rounding."""
    hessian = known[1][0]
    gradient = _moved_gradient(known, change)
    return state - dense.damped_solve(hessian, PREDICTION_DAMPING, gradient)


def start_linearisation(mech: Mechanism, kind: str, geom: Geometry, values, state):
    """The walk's ``known`` at its start (None on the band)."""
    if banded.serves(mech):
        return None
    residual, *model = jacobian.normal_equations_tail(mech, geom, kind, values, state)
    return residual, tuple(model)


@jax.tree_util.register_dataclass
@dataclass(frozen=True)
class _Walk:
    """Continuation carry: ``fraction`` of the way done at ``state``, next ``step``."""

    fraction: Float[Array, ""]
    step: Float[Array, ""]
    state: Float[Array, " S"]
    iterations: Int[Array, ""]
    steps: Int[Array, ""]
    stuck: Bool[Array, ""]


@dataclass(frozen=True)
class _Line:
    """What a walk holds fixed: where it goes and its step bounds."""

    mech: Mechanism
    kind: str
    geom: Geometry
    v_from: Float[Array, " k"]
    delta: Float[Array, " k"]  # v_to - v_from
    smallest: Float[Array, ""]
    largest: Float[Array, ""]

    def values(self, fraction):
        return self.v_from + fraction * self.delta


def _judged(line: _Line, walk: _Walk, target, predicted, x, residual, iterations):
    """The walk after a step to ``target`` whose corrector went from ``predicted`` to
    ``x`` (residual vector ``residual`` there) in ``iterations``: accepted iff
    converged near the prediction (module docstring); and whether it was."""
    converged = jnp.max(jnp.abs(residual)) <= line.mech.solver.tolerance
    correction = jnp.max(jnp.abs(x - predicted))
    move = jnp.max(jnp.abs(predicted - walk.state))
    ok = converged & (correction <= PREDICTION_RATIO * move + PREDICTION_SLACK)
    step = jnp.where(ok, jnp.minimum(2.0 * walk.step, line.largest), 0.5 * walk.step)
    return _Walk(
        fraction=jnp.where(ok, target, walk.fraction),
        step=step,
        state=jnp.where(ok, x, walk.state),
        iterations=walk.iterations + iterations.astype(walk.iterations.dtype),
        steps=walk.steps + 1,
        stuck=(~ok) & (step < line.smallest),
    ), ok


def _going(walk: _Walk) -> Bool[Array, ""]:
    return (walk.fraction < 1.0) & ~walk.stuck & (walk.steps < MAX_STEPS)


def _advance(line: _Line, walk: _Walk) -> _Walk:
    """One predictor-corrector step of the band's nested walk: the first-order
    prediction, at most ``chord.LIMIT`` chord steps from it (:func:`.banded.predict`;
    the limit read when the walk is traced), the
    LM corrector from there; the acceptance test measures the corrector's move from
    the first-order prediction (module docstring)."""
    target = jnp.minimum(walk.fraction + walk.step, 1.0)
    values = line.values(target)
    if banded.serves(line.mech):
        predicted, start = banded.predict(
            line.mech, line.kind, line.geom, values, walk.state, chord.LIMIT
        )
    else:  # the nested walk on the dense path: nested_walk's, a test's reference
        predicted = start = predict(line.mech, line.kind, line.geom, values, walk.state)
    result = corrector(line.mech, line.kind, line.geom, values, start)
    residual = result.linearisation[0]
    return _judged(
        line, walk, target, predicted, result.x, residual, result.iterations
    )[0]


@jax.tree_util.register_dataclass
@dataclass(frozen=True)
class _Pass:
    """The dense walk's carry: the walk, the normal equations ``known`` at its state
    (``(C, (JᵀJ, JᵀC, J_tail))``), and the step in progress: its ``target`` fraction,
    ``predicted`` state and corrector; ``fresh`` when the next pass starts a step."""

    walk: _Walk
    known: tuple
    target: Float[Array, ""]
    predicted: Float[Array, " S"]
    corrector: lm.LMState
    fresh: Bool[Array, ""]


def _dense_pass(line: _Line, p: _Pass) -> _Pass:
    """One damped solve and one linearisation: a new step's prediction where
    ``fresh``, else the corrector's next trial; then, where the corrector has
    finished, the walk's verdict on the step."""
    settings = line.mech.solver
    walk, fresh, c = p.walk, p.fresh, p.corrector
    target = jnp.where(fresh, jnp.minimum(walk.fraction + walk.step, 1.0), p.target)
    values = line.values(target)
    hessian = jnp.where(fresh, p.known[1][0], c.model[0])
    gradient = jnp.where(
        fresh, _moved_gradient(p.known, values - line.values(walk.fraction)), c.model[1]
    )
    damping = jnp.where(fresh, PREDICTION_DAMPING, c.damping)
    delta, decrease = lm.normal_step(hessian, gradient, damping)
    trial = jnp.where(fresh, walk.state, c.x) + delta
    residual, *model = jacobian.normal_equations_tail(
        line.mech, line.geom, line.kind, values, trial
    )
    model = tuple(model)
    started = lm.initial_state(trial, residual, model, settings.initial_damping)
    stepped = lm.update(c, trial, delta, decrease, residual, model)
    c = jax.tree.map(lambda a, b: jnp.where(fresh, a, b), started, stepped)
    predicted = jnp.where(fresh, trial, p.predicted)
    done = lm.finished(c, settings.tolerance, settings.max_iterations)
    judged, ok = _judged(line, walk, target, predicted, c.x, c.residual, c.iteration)
    keep = ok & done
    return _Pass(
        walk=jax.tree.map(lambda a, b: jnp.where(done, a, b), judged, walk),
        known=jax.tree.map(
            lambda a, b: jnp.where(keep, a, b), (c.residual, c.model), p.known
        ),
        target=target,
        predicted=predicted,
        corrector=c,
        fresh=done,
    )


def _dense_walk(line: _Line, walk: _Walk, known) -> tuple[_Walk, tuple]:
    if known is None:
        known = start_linearisation(
            line.mech, line.kind, line.geom, line.v_from, walk.state
        )
    start = _Pass(
        walk=walk,
        known=known,
        target=walk.fraction,
        predicted=walk.state,
        corrector=lm.initial_state(
            walk.state, known[0], known[1], line.mech.solver.initial_damping
        ),
        fresh=jnp.asarray(True),
    )
    end = jax.lax.while_loop(
        lambda p: ~p.fresh | _going(p.walk), lambda p: _dense_pass(line, p), start
    )
    return end.walk, end.known


def _line(mech: Mechanism, kind: str, geom: Geometry, v_from, state, v_to):
    """The walk's fixed :class:`_Line` and its first :class:`_Walk`."""
    v_from = jnp.asarray(v_from, dtype=jnp.float64)
    delta = v_to - v_from
    span = jnp.maximum(jnp.max(jnp.abs(delta)), MIN_STEP)
    largest = jnp.minimum(1.0, MAX_STEP / span)
    line = _Line(mech, kind, geom, v_from, delta, MIN_STEP / span, largest)
    start = _Walk(
        fraction=jnp.where(jnp.max(jnp.abs(delta)) > 0, 0.0, 1.0),
        step=largest,
        state=state,
        iterations=jnp.zeros((), dtype=jnp.int32),
        steps=jnp.zeros((), dtype=jnp.int32),
        stuck=jnp.zeros((), dtype=bool),
    )
    return line, start


def walk(
    mech: Mechanism, kind: str, geom: Geometry, v_from, state, v_to, known=None
) -> tuple[Float[Array, " S"], Float[Array, ""], Int[Array, ""], tuple | None]:
    """From ``state`` (solved at values ``v_from``) towards values ``v_to``, all
    homogenised and held constant (no derivative flows through the walk): the last
    state reached on the start's branch, the fraction of the way reached there (1 when
    the whole way was), the LM iterations taken, and the normal equations at the state
    reached (``known``, None on the band), which a walk that goes on from there takes
    as its own ``known`` instead of linearising its start again (a path's next row:
    :func:`linkopt._engine.kinematics.continue_to`)."""
    if banded.serves(mech):
        return (*nested_walk(mech, kind, geom, v_from, state, v_to), None)
    line, start = _line(mech, kind, geom, v_from, state, v_to)
    end, known = _dense_walk(line, start, known)
    return end.state, end.fraction, end.iterations, known


def nested_walk(
    mech: Mechanism, kind: str, geom: Geometry, v_from, state, v_to
) -> tuple[Float[Array, " S"], Float[Array, ""], Int[Array, ""]]:
    """:func:`walk` as a loop of steps around each corrector's own LM loop, each step
    predicted afresh (:func:`_advance`): the band's walk, and on the dense path the
    reference the one loop is tested against (``tests/test_continuation_walk.py``)."""
    line, start = _line(mech, kind, geom, v_from, state, v_to)
    end = jax.lax.while_loop(_going, lambda w: _advance(line, w), start)
    return end.state, end.fraction, end.iterations
