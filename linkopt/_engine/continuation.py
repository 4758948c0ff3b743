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

**Failing fast.** On the dense path a step's corrector gets at most ``STEP_ITERATIONS``
(8) LM iterations, not the file's ``max_iterations`` (60 by default); one that has not
converged by then rejects the step, which halves. From a first-order prediction an
accepted step converges in about three (the shipped files from rest, rows within ±0.8
rad or reference lengths, so at least four steps of ``MAX_STEP``: 6.8-15 iterations a
row on average; the cap at 6 already changed none of them). A row with no assembly on
its branch (past the linkage's reach) ends only once its step has halved to ``MIN_STEP``
at the edge of the reach, about 40 steps, and the steps past the edge never converge:
each took all 60 iterations, so on the five-bar such a row cost about 760 iterations
where a reached one costs 4-11, and every lane of its vmapped chunk waited for it. With
the cap it costs about 270. Measured on 2026-12-07 (64 rows within ±0.8 of rest for each
of the 21 shipped files, one process, against the cap of 60): the same rows converge, to
bitwise the same states, in the same LM iterations but for 4 rows of the spherical
five-bar, which took fewer (a step rejected on their way gave up sooner); a failing
row's last state moves by at most 2e-3 (a step near the edge that converged in more than
8 iterations is now halved instead); the sweeps took 6.8 s instead of 25.8 s (the
Stewart platform, 98 % of its rows past the reach, 9.0 -> 2.2 s); and the ``f_design``
of 8 files' evaluations and the main job's are bitwise the same.
``benchmarks/bench_kinematics.py --beyond-only`` measures it.

The cap is the dense path's only. On the band (:func:`.banded.serves`: 20 bodies and
more) the soft modes of long chains make a step's corrector converge slowly, and with
the cap lazy tongs of 300 bodies failed to reach -1.0 and -1.5 rad (progress 0.85 and
0.57), which they reach with the file's cap in 419 and 104 iterations; there every step
keeps the file's cap. Soft chains on the dense path still reach their rows with the
cap, in more iterations where a step is halved: lazy tongs of 16 bodies, rows at ±1,
±1.5 and ±2 rad, took 17-59 iterations against 17-49, to states 7e-11 apart (19
bodies: 9.9e-10; 10 bodies: the same 15-35 iterations).

On the dense path each step's prediction reuses the last accepted step's normal
equations, with the motor or output rows moved by the values' change
(:func:`predict_from`): no linearisation per prediction. A walk returns the normal
equations at the state it reached, and a walk that goes on from there (a path's next
row) starts from them instead of linearising its start again.

One loop of linearisations instead of the nested loops (each pass a step's prediction or
the corrector's next trial) was measured on 2026-12-07 and not kept: the program held
the linearisation twice instead of three times (five-bar from rest 3,004 -> 2,402 jaxpr
equations), but every pass selected between the carried normal equations and the
corrector's (``JᵀJ``-sized selects, several per pass where the nested loops make about
one per iteration), and ``benchmarks/bench_kinematics.py --wide-only`` ran it 0.86x
(five-bar) and 0.75x (Jansen leg) as fast, idle, alternating. That machine's noise was
as large (one tree against itself: 1.78x and 0.70x), so the measurement does not decide;
the nested loops stay, whose results are the earlier program's bit for bit.

On the band (:mod:`.banded`, long linkages) the prediction linearises afresh
(:func:`.banded.predict`), and is followed by chord steps with the rows and factor it
was made with (:mod:`.solvers.chord`) before the LM corrector. A long linkage's lever
arm grows the prediction's error, and with it the LM iterations, each a new band
assembly and factor; a chord step costs a residual and two scans.
``benchmarks/bench_bodies.py``'s rows (SPAN 0.05 rad, 16 rows, CPU per solve, against
the walk without them in one process, load 6-7): ladder of 300 bodies 27.9 -> 7.1 ms (LM
iterations per solve 6.06 -> 0), lazy tongs of 100 bodies 5.3 -> 1.3 ms (8.06 -> 0). On
the dense path (five-bar, Jansen leg, ±0.3 rad from rest) the same steps cut the LM
iterations (4.1 -> 1.0 per solve) but not the time (a chord step there cost about what
the LM iteration it saved did), so the dense walk has none. ``Solution.iterations``
counts LM iterations, not chord steps.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import jax
import jax.numpy as jnp
from jaxtyping import Array, Bool, Float, Int

from . import banded, dense, jacobian
from .constraints import RESIDUALS
from .geometry import Geometry
from .model import Mechanism
from .solvers import chord, lm

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
#: Most LM iterations of one step's corrector on the dense path (the file's ``[solver]
#: max_iterations`` where that is lower): a step whose corrector has not converged by
#: then is rejected and halved (module docstring, "Failing fast").
STEP_ITERATIONS = 8
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
    """LM on ``C(values, s)`` from ``start`` with the file's ``[solver]`` settings, on
    the band where :func:`.banded.serves` says so, with the geodesic acceleration and
    the damping scaled with ``|C|²`` where :func:`.banded.geodesic` does
    (``with_tail``: the result's linearisation holds the motor or output rows'
    Jacobian too, for :func:`predict_from`); ``max_iterations`` replaces the file's
    iteration cap where given."""
    settings = mech.solver
    linearise = (
        jacobian.normal_equations_tail if with_tail else jacobian.normal_equations
    )
    method = lm.NormalEquations(
        lambda s: RESIDUALS[kind](mech, geom, values, s),
        lambda s: linearise(mech, geom, kind, values, s),
    )
    long = False
    if banded.serves(mech):
        long = banded.geodesic(mech)
        method = banded.Banded(mech, geom, kind, values, long)
    return lm.solve(
        method,
        start,
        tolerance=settings.tolerance,
        max_iterations=(
            settings.max_iterations if max_iterations is None else max_iterations
        ),
        initial_damping=settings.initial_damping,
        residual_scaled=long,
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
    #: the dense solves' ``(C, (JᵀJ, JᵀC, J_tail))`` at ``state`` and the values
    #: reached (:func:`predict_from`); None on the band and in :func:`nested_walk`
    known: object = None


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
    """One predictor-corrector step: on the band the first-order prediction and at
    most ``chord.LIMIT`` chord steps from it (:func:`.banded.predict`; the limit read
    when the walk is traced); on the dense path the prediction from the carried normal
    equations (:func:`predict_from`), or made afresh (:func:`predict`) where the walk
    carries none; then the LM corrector. The acceptance test measures the corrector's
    move from the first-order prediction (module docstring)."""
    target = jnp.minimum(walk.fraction + walk.step, 1.0)
    values = line.values(target)
    mech, kind, geom = line.mech, line.kind, line.geom
    if banded.serves(mech):
        predicted, start = banded.predict(
            mech, kind, geom, values, walk.state, chord.LIMIT
        )
    elif walk.known is None:
        predicted = start = predict(mech, kind, geom, values, walk.state)
    else:
        change = values - line.values(walk.fraction)
        predicted = start = predict_from(walk.state, walk.known, change)
    carried = walk.known is not None
    cap = None  # the band's long, soft linkages: the file's cap (module docstring)
    if not banded.serves(mech):
        cap = jnp.minimum(STEP_ITERATIONS, mech.solver.max_iterations)
    result = corrector(mech, kind, geom, values, start, cap, with_tail=carried)
    judged, ok = _judged(
        line,
        walk,
        target,
        predicted,
        result.x,
        result.linearisation[0],
        result.iterations,
    )
    if not carried:
        return judged
    known = jax.tree.map(
        lambda new, old: jnp.where(ok, new, old), result.linearisation, walk.known
    )
    return dataclasses.replace(judged, known=known)


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
    line, start = _line(mech, kind, geom, v_from, state, v_to)
    if not banded.serves(mech):
        if known is None:
            known = start_linearisation(mech, kind, geom, line.v_from, state)
        start = dataclasses.replace(start, known=known)
    end = jax.lax.while_loop(_going, lambda w: _advance(line, w), start)
    return end.state, end.fraction, end.iterations, end.known


def nested_walk(
    mech: Mechanism, kind: str, geom: Geometry, v_from, state, v_to
) -> tuple[Float[Array, " S"], Float[Array, ""], Int[Array, ""]]:
    """:func:`walk` with every step predicted afresh (:func:`predict`, no normal
    equations carried): on the dense path the reference the carried predictions are
    tested against (``tests/test_continuation_walk.py``)."""
    line, start = _line(mech, kind, geom, v_from, state, v_to)
    end = jax.lax.while_loop(_going, lambda w: _advance(line, w), start)
    return end.state, end.fraction, end.iterations
