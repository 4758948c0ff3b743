"""Forward and backward kinematics solves, continuation paths and implicit
sensitivities.

Public functions take motor values ``a`` and outputs ``b`` in file units (rad for
angles) and return homogenised states. Every solve is jitted with the mechanism as a
static argument; a leading batch axis on ``a``/``b`` (and optionally the start state)
is vmapped, so a batch never recompiles for a new design vector.

Branches: a solve without a start state reaches the requested values by continuation
from the rest pose (:func:`continue_to`): bounded steps, each predicted to first order
(``s + ds/dv Δv``) and corrected by Levenberg–Marquardt, a step accepted only when the
corrector lands near the prediction, halved otherwise. The answer is then on the rest
pose's assembly branch, or the solve reports ``converged = False`` with the fraction
of the way it reached (``Solution.progress``): past that value there is no assembly on
this branch, or the branch passes a singularity. Path solves continue the same way from
row to row. A solve given a start state is one plain LM solve from it, for callers
(samplers, maps, sensitivities) whose start is already next to the answer.

Derivatives (paper eq. 2): the solved state is attached to its inputs by
:func:`implicit_state`, whose JVP is the implicit-function-theorem tangent
``ṡ = -(JᵀJ)⁻¹ Jᵀ (∂C/∂a ȧ + ∂C/∂p ṗ)`` with ``J = ∂C/∂s``. For ``f_FK = 0`` this is
eq. 2 (the Gauss–Newton Hessian is exact there); with redundant rows ``J`` is tall and
the formula is the least-squares tangent. Both forward and reverse mode work through it.
"""

from __future__ import annotations

import weakref
from dataclasses import dataclass
from functools import partial

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Bool, Float, Int

from .._config import jit, stored_record, traced
from .._errors import InputError
from . import banded, continuation, dense, jacobian, programs
from .arguments import check_arguments, check_design, check_state, value_scale
from .blocks import first_rows, in_blocks, path_rows
from .constraints import (
    RESIDUALS,
    homogenised_motor_values,
    homogenised_output_values,
)
from .geometry import Geometry, design_array, design_vector, geometry, rest_state
from .model import Mechanism

_VALUES = {"fk": homogenised_motor_values, "bk": homogenised_output_values}


@stored_record("linkopt.Solution")
@dataclass(frozen=True)
class Solution:
    """A kinematics solve; leading axes follow the batch/path of the inputs."""

    state: Float[Array, "... S"]  # homogenised state
    converged: Bool[Array, ...]
    residual: Float[Array, ...]  # max |C| at state (homogenised)
    iterations: Int[Array, ...]  # LM iterations, summed over continuation steps
    #: fraction of the way from the start's values to the requested ones that the
    #: continuation reached on the start's branch (1 when converged)
    progress: Float[Array, ...]


@partial(jax.custom_jvp, nondiff_argnums=(0,))
def implicit_state(kind: str, mech: Mechanism, geom: Geometry, values, state):
    """Identity on ``state``; carries the implicit-function derivative (module
    docstring) in the geometry and the values. The mechanism is an argument, not a
    nondiff one (inside a program its numbers are tracers, which a nondiff argument
    would keep past its trace); its numbers reach the derivative through the
    geometry, and their own tangent is dropped, so the rule computes what it did
    when the mechanism was static."""
    return state


@implicit_state.defjvp
def _implicit_state_jvp(kind, primals, tangents):
    mech, geom, values, state = primals
    _, d_geom, d_values, _ = tangents
    residual = RESIDUALS[kind]
    _, rhs = jax.jvp(
        lambda g, v: residual(mech, g, v, state), (geom, values), (d_geom, d_values)
    )
    if banded.serves(mech):
        return state, banded.tangent(mech, kind, geom, values, state, residual, rhs)
    jac = jacobian.state_jacobian(mech, geom, kind, state)
    d_state = -dense.solve_spd(jac.T @ jac, jac.T @ rhs)
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
    result = continuation.corrector(
        mech,
        kind,
        jax.lax.stop_gradient(geom),
        jax.lax.stop_gradient(values),
        jax.lax.stop_gradient(start),
        max_iterations,
    )
    state = implicit_state(kind, mech, geom, values, result.x)
    progress = result.converged.astype(jnp.float64)
    return Solution(
        state, result.converged, result.residual, result.iterations, progress
    )


def continue_to(
    mech: Mechanism, kind: str, geom: Geometry, v_from, state, v_to
) -> Solution:
    """Continuation from ``state`` (solved at values ``v_from``) to values ``v_to``, all
    homogenised, along the straight line between them (:mod:`.continuation`).

    Not converged when the branch has no assembly past some value, or passes a
    singularity, on the way: ``progress`` says how far it got, and ``state`` is the
    last state reached on the branch."""
    return _continued(mech, kind, geom, v_from, state, v_to)[0]


def _continued(
    mech: Mechanism, kind: str, geom: Geometry, v_from, state, v_to, known=None
):
    """:func:`continue_to`, and the normal equations at the state reached
    (:func:`.continuation.walk`'s ``known``, taken as given here)."""
    fixed_geom = jax.lax.stop_gradient(geom)
    fixed_to = jax.lax.stop_gradient(v_to)
    reached, fraction, iterations, known = continuation.walk(
        mech,
        kind,
        fixed_geom,
        jax.lax.stop_gradient(jnp.asarray(v_from, dtype=jnp.float64)),
        jax.lax.stop_gradient(state),
        fixed_to,
        known,
    )
    residual = jnp.max(jnp.abs(RESIDUALS[kind](mech, fixed_geom, fixed_to, reached)))
    converged = (fraction >= 1.0) & (residual <= mech.solver.tolerance)
    final = implicit_state(kind, mech, geom, v_to, reached)
    return Solution(final, converged, residual, iterations, fraction), known


def _prepare(mech: Mechanism, kind: str, values, start, design):
    values = jnp.asarray(values, dtype=jnp.float64) / value_scale(mech, kind)
    start = rest_state(mech) if start is None else jnp.asarray(start, dtype=jnp.float64)
    return values, start, geometry(mech, design_vector(mech, design))


#: Lanes per vmapped chunk of a batched solve (``lax.map`` runs the chunks in turn).
#: A whole batch vmapped at once makes every operation of the solve (the plain-JAX
#: Cholesky's column steps above all) stream the batch's matrices through memory; in
#: chunks they stay in cache, which runs several times faster
#: (``benchmarks/bench_kinematics.py`` times batched solves).
CHUNK = 32


def _chunked(fn, xs):
    """``vmap(fn)(xs)`` computed ``CHUNK`` lanes at a time."""
    return jax.lax.map(fn, xs, batch_size=CHUNK)


@partial(jit, static_argnums=1)
def solve_batch(mech: Mechanism, kind: str, values, start, design) -> Solution:
    values, start, geom = _prepare(mech, kind, values, start, design)
    if values.ndim == 1:
        return solve_single(mech, kind, geom, values, start)
    if start.ndim == 2:
        return _chunked(lambda vs: solve_single(mech, kind, geom, *vs), (values, start))
    return _chunked(lambda v: solve_single(mech, kind, geom, v, start), values)


@partial(jit, static_argnums=1)
def solve_batch_from_rest(mech: Mechanism, kind: str, values, design) -> Solution:
    values, start, geom = _prepare(mech, kind, values, None, design)
    v_rest = _VALUES[kind](mech, geom, start)

    def one(v):
        return continue_to(mech, kind, geom, v_rest, start, v)

    return one(values) if values.ndim == 1 else _chunked(one, values)


@partial(jit, static_argnums=1)
def _solve_path(mech: Mechanism, kind: str, values, start, design) -> Solution:
    values, start, geom = _prepare(mech, kind, values, start, design)

    def advance(carry, v):
        v_from, state, known = carry
        solution, known = _continued(mech, kind, geom, v_from, state, v, known)
        reached = v_from + solution.progress * (v - v_from)
        return (reached, jax.lax.stop_gradient(solution.state), known), solution

    # each row's walk starts from the normal equations the last one ended with: they
    # are those at its state and values (the first row's, of the start, made here)
    v_start = _VALUES[kind](mech, geom, start)
    fixed = jax.lax.stop_gradient
    known = continuation.start_linearisation(
        mech, kind, fixed(geom), fixed(v_start), fixed(start)
    )
    _, solutions = jax.lax.scan(advance, (v_start, start, known), values)
    return solutions


def _warm(mech: Mechanism, kind: str, values, start, design) -> Solution:
    """:func:`solve_batch`; a concrete batch in fixed blocks (:mod:`.blocks`), each row
    with its own start. Concrete calls here and below keep their traces on disk
    (:func:`.programs.call`: a warm process skips tracing a solve)."""
    if traced(mech, values, start, design):
        return solve_batch(mech, kind, values, start, design)
    design = design_array(mech, design)
    values = np.asarray(values, dtype=np.float64)
    start = np.asarray(start, dtype=np.float64)

    def solve(v, s):
        return programs.call(
            f"solve_{kind}", mech, lambda m, *a: solve_batch(m, kind, *a), v, s, design
        )

    if values.ndim == 1:
        return solve(values, start)
    # no single-row shortcut (``in_blocks``'s ``one``): warm-started batches are the
    # maps' and verification's waves, whose first wave of one cell would compile the
    # one-row program beside the block's (seconds of the cold main command's
    # compilation, benchmarks/bench_compile.py)
    starts = np.broadcast_to(start, (len(values), mech.state_size))
    return in_blocks(solve, (values, starts))


def _from_rest(mech: Mechanism, kind: str, values, design) -> Solution:
    """:func:`solve_batch_from_rest`; a concrete batch in fixed blocks."""
    if traced(mech, values, design):
        return solve_batch_from_rest(mech, kind, values, design)
    design = design_array(mech, design)
    values = np.asarray(values, dtype=np.float64)

    def solve(v):
        return programs.call(
            f"from_rest_{kind}",
            mech,
            lambda m, *a: solve_batch_from_rest(m, kind, *a),
            v,
            design,
        )

    if values.ndim == 1:
        return solve(values)
    order = span_order(mech, kind, values)
    solved = in_blocks(solve, (values[order],), one=solve)
    back = np.argsort(order)  # in numpy: a jax gather compiled per batch size
    return jax.tree.map(lambda a: jax.device_put(np.asarray(a)[back]), solved)


def span_order(mech: Mechanism, kind: str, values: np.ndarray) -> np.ndarray:
    """The rows of a concrete batch by distance from the rest values (the file's
    design): a vmapped chunk's loops run until its slowest lane is done, and rows of
    like span take like numbers of steps and iterations (in random order, nearly every
    chunk took the two steps of its farthest row). Each row's solve is the same."""
    rest = _rest_values(mech, kind)
    span = np.max(np.abs(values / np.asarray(value_scale(mech, kind)) - rest), axis=-1)
    return np.argsort(span, kind="stable")


#: :func:`_rest_values` of each mechanism by kind, weakly held (a process that goes
#: through many mechanisms keeps none of them alive).
_REST_VALUES: weakref.WeakKeyDictionary[Mechanism, dict] = weakref.WeakKeyDictionary()


def _rest_values(mech: Mechanism, kind: str) -> np.ndarray:
    """Homogenised motor or output values of the rest state at the file's design,
    read by the stored read-out programs (op by op, a few small programs compiled in
    every process)."""
    from .readout import motor_values, output_values  # local: avoid an import cycle

    held = _REST_VALUES.setdefault(mech, {})
    if kind not in held:
        read = motor_values if kind == "fk" else output_values
        values = np.asarray(read(mech, np.asarray(rest_state(mech))))
        held[kind] = values / np.asarray(value_scale(mech, kind))
    return held[kind]


def _along(mech: Mechanism, kind: str, values, start, design) -> Solution:
    """:func:`_solve_path`; a concrete path padded to :func:`.blocks.path_rows` rows
    (repeats of its last row, continuations of length zero), then cut back."""
    if traced(mech, values, start, design):
        return _solve_path(mech, kind, values, start, design)
    values = np.asarray(values, dtype=np.float64)
    count = len(values)
    padded = np.concatenate(
        [values, np.repeat(values[-1:], path_rows(count) - count, axis=0)]
    )
    start = rest_state(mech) if start is None else start  # one program for both
    solution = programs.call(
        f"path_{kind}",
        mech,
        lambda m, *a: _solve_path(m, kind, *a),
        padded,
        np.asarray(start, dtype=np.float64),
        design_array(mech, design),
    )
    return first_rows(solution, count)


def solve_fk(mech: Mechanism, motors, *, start=None, design=None) -> Solution:
    """Forward kinematics: motors ``(M,)`` or a batch ``(N, M)`` -> states.

    Without ``start``, each solve continues from the rest pose to its motor values, so
    its answer is on the rest pose's assembly branch or it is not converged (module
    docstring). ``start`` is a warm start instead (homogenised state ``(S,)`` or
    ``(N, S)``), solved from by one LM solve; ``design`` the design vector (default the
    file's). Differentiable in ``motors`` and ``design`` through the implicit function
    theorem.
    """
    check_arguments(mech, "fk", motors, start, design, path=False)
    if start is None:
        return _from_rest(mech, "fk", motors, design)
    return _warm(mech, "fk", motors, start, design)


def solve_bk(mech: Mechanism, outputs, *, start=None, design=None) -> Solution:
    """Backward kinematics: outputs ``(K,)`` or ``(N, K)`` -> states (motors read off
    them); ``start`` as for :func:`solve_fk`."""
    check_arguments(mech, "bk", outputs, start, design, path=False)
    if start is None:
        return _from_rest(mech, "bk", outputs, design)
    return _warm(mech, "bk", outputs, start, design)


def solve_fk_path(mech: Mechanism, motors, *, start=None, design=None) -> Solution:
    """Continuation along motor values ``(T, M)`` from ``start`` (default the rest
    state, which must be assembled): each row is reached from the previous one in
    predictor-corrector steps that are subdivided until they stay on the branch of
    ``start``; a row the branch cannot reach is not converged, and later rows continue
    from the last state reached."""
    check_arguments(mech, "fk", motors, start, design, path=True)
    return _along(mech, "fk", motors, start, design)


def solve_bk_path(mech: Mechanism, outputs, *, start=None, design=None) -> Solution:
    """Continuation along outputs ``(T, K)``, as :func:`solve_fk_path`."""
    check_arguments(mech, "bk", outputs, start, design, path=True)
    return _along(mech, "bk", outputs, start, design)


_WRT = ("motors", "outputs", "design", "design_bk")


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

    if not (isinstance(wrt, str) and wrt in _WRT):
        raise InputError(f"wrt: expected one of {', '.join(_WRT)}, got {wrt!r}")
    check_state(mech, state)
    check_design(mech, design)
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
    raise AssertionError(wrt)  # unreachable: checked above
