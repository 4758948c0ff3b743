"""Solving an assembly problem: the residual of its rows and the nearest assembly to the
drawing (minimum-norm Levenberg–Marquardt, then projection onto the nearest point of
the constraint manifold, then a polish; the package docstring gives the choices).

The Levenberg–Marquardt phases are :mod:`linkopt._engine.solvers.lm`'s loop with its
:class:`~linkopt._engine.solvers.lm.MinimumNorm` step: an assembly is underdetermined
(every anchor of a body given by world anchors, six unknowns per frame, more than the
rows), so the step is the minimum-norm one through ``J Jᵀ`` in weighted variables, which
the projection after it (:mod:`linkopt._engine.solvers.projection`) needs (``JᵀJ``
there is singular up to λ).
"""

from __future__ import annotations

import dataclasses
import functools
import importlib

import numpy as np

from ..._engine.rotations import matrix_exp
from .problem import Problem, Rows

#: Frame variables (position and rotation vector) weigh this in the movement norm,
#: against 1 for anchors: a frame moves freely but not for nothing (a body with two
#: anchors still has a definite rotation about their line).
FRAME_WEIGHT = 1e-2
#: max |residual| (reference lengths, rad) below which the loops are closed.
CLOSE_TOL = 1e-10
#: Minimum-norm LM: its stopping max |residual|, initial damping and iteration cap.
LM_TOLERANCE = 1e-15
LM_DAMPING = 1e-6
#: Iteration caps: minimum-norm LM, projection onto the nearest assembly.
LM_ITERATIONS = 400
PROJECTION_ITERATIONS = 100


def start(problem: Problem) -> np.ndarray:
    """Drawn anchors, then the drawn frames (position, zero rotation vector)."""
    frames = np.concatenate(
        [problem.frames0, np.zeros_like(problem.frames0)], axis=1
    ).ravel()
    return np.concatenate([problem.anchors0.ravel(), frames])


def weights(problem: Problem) -> np.ndarray:
    """Per variable, the square root of its inverse weight in the movement norm; zero
    for held anchors."""
    anchors = np.repeat(np.where(problem.held, 0.0, 1.0), 3)
    frames = np.full(6 * len(problem.frame_names), FRAME_WEIGHT**-0.5)
    return np.concatenate([anchors, frames])


def solve(problem: Problem, x0: np.ndarray, rows: Rows):
    """Assemble from ``x0``: (x, max |residual|, iterations)."""
    lm, project, _ = _programs()
    sizes = (len(problem.joint_names), len(problem.frame_names))
    s = weights(problem)
    x, first = lm(sizes, rows, x0, s)
    residual = float(np.max(np.abs(residual_np(sizes, rows, x)), initial=0.0))
    if residual <= CLOSE_TOL and len(x):
        y, steps = project(sizes, rows, x, x0, s)
        y, polish = lm(sizes, rows, y, s)
        after = float(np.max(np.abs(residual_np(sizes, rows, y)), initial=0.0))
        if after <= CLOSE_TOL and _moved(y, x0, s) <= _moved(x, x0, s) + 1e-12:
            return np.asarray(y), after, int(first) + int(steps) + int(polish)
    return np.asarray(x), residual, int(first)


def _moved(x, x0, s) -> float:
    return float(
        np.sum(np.where(s > 0, (np.asarray(x) - x0) / np.where(s > 0, s, 1), 0) ** 2)
    )


def residual_np(sizes, rows, x) -> np.ndarray:
    return np.asarray(_programs()[2](sizes, rows, x))


def without_motors(rows: Rows) -> Rows:
    motors = [f.name for f in dataclasses.fields(Rows) if f.name.startswith("motor_")]
    return dataclasses.replace(rows, **{k: getattr(rows, k)[:0] for k in motors})


def _residual(sizes: tuple[int, int], rows: Rows, x):
    """Length rows, local-anchor rows (3 each), slide-line rows (2 each), axis rows,
    motor rows; homogenised (rad for axes and rotary motors)."""
    import jax.numpy as jnp

    joints, frames = sizes
    a = x[: 3 * joints].reshape(joints, 3)
    pose = x[3 * joints :].reshape(frames, 6)
    d = a[rows.pairs[:, 0]] - a[rows.pairs[:, 1]]
    lengths = jnp.sqrt(jnp.sum(d * d, axis=-1) + 1e-300) - rows.lengths
    turn = matrix_exp(pose[:, 3:])
    rot = jnp.einsum("fij,fjk->fik", turn, rows.rotation0)
    image = pose[rows.local_frame, :3] + jnp.einsum(
        "rij,rj->ri", rot[rows.local_frame], rows.local_at
    )
    local = (a[rows.local_joint] - image).ravel()
    on_line = pose[rows.line_frame, :3] + jnp.einsum(
        "sij,sj->si", rot[rows.line_frame], rows.line_at
    )
    normals = jnp.einsum("sij,skj->ski", turn[rows.line_frame], rows.line_n)
    line = jnp.einsum("ski,si->sk", normals, a[rows.line_joint] - on_line).ravel()
    carry = jnp.concatenate([jnp.eye(3)[None], turn])  # index: frame + 1
    p = jnp.einsum("aij,aj->ai", carry[rows.axis_p + 1], rows.axis_vp)
    q = jnp.einsum("aij,aj->ai", carry[rows.axis_q + 1], rows.axis_vq)
    axes = jnp.sum(p * q, axis=-1)
    motors = _motor_residual(rows, a, carry[rows.motor_frame + 1])
    return jnp.concatenate([lengths, local, line, axes, motors])


def _motor_residual(rows: Rows, a, carry):
    """Held motors, about their axes as their first bodies carry them (``carry``
    ``(M, 3, 3)``: each first body's turn from the drawing)."""
    import jax.numpy as jnp

    def turned(v):
        return jnp.einsum("mij,mj->mi", carry, v)

    axis, e, f = turned(rows.motor_axis), turned(rows.motor_e), turned(rows.motor_f)
    pivot = a[rows.motor_joint]
    has_base = rows.motor_base >= 0
    base = a[jnp.maximum(rows.motor_base, 0)]
    v = a[rows.motor_moved] - pivot
    w = base - pivot

    def angle(u):
        return jnp.arctan2(jnp.sum(u * f, axis=-1), jnp.sum(u * e, axis=-1))

    turn = angle(v) - jnp.where(has_base, angle(w), 0.0) - rows.motor_target
    rotary = jnp.arctan2(jnp.sin(turn), jnp.cos(turn))
    ref = jnp.where(has_base[:, None], base, pivot)
    linear = jnp.sum((a[rows.motor_moved] - ref) * axis, -1)
    return jnp.where(rows.motor_linear, linear - rows.motor_target, rotary)


@functools.cache
def _programs():
    """The jitted solver stages, built on first use: a file that declares no assembly
    is read without JAX. :mod:`linkopt._config` comes first, so JAX starts in float64;
    every other JAX use in this package runs after this, inside these programs or on
    their results."""
    from ..._config import jit
    from ..._engine.solvers import lm as _lm
    from ..._engine.solvers.driver import run
    from ..._engine.solvers.projection import Projection

    jax = importlib.import_module("jax")  # after linkopt._config: float64 on
    jnp = jax.numpy
    jax.tree_util.register_dataclass(Rows)  # a program argument: every field an array

    @functools.partial(jit, static_argnums=0)
    def lm(sizes, rows, x, s):
        """Levenberg–Marquardt with least-norm steps (``lm.MinimumNorm``)."""
        if x.size == 0:  # nothing to solve
            return x, jnp.asarray(0)
        method = _lm.MinimumNorm(lambda y: _residual(sizes, rows, y), s)
        result = _lm.solve(
            method,
            x,
            tolerance=LM_TOLERANCE,
            max_iterations=LM_ITERATIONS,
            initial_damping=LM_DAMPING,
        )
        return result.x, result.iterations

    @functools.partial(jit, static_argnums=0)
    def project(sizes, rows, x, x0, s):
        """Gauss–Newton projection onto the assembly nearest the drawing."""
        method = _lm.MinimumNorm(lambda y: _residual(sizes, rows, y), s)
        state, _ = run(Projection(method, x0), x, PROJECTION_ITERATIONS)
        return state.x, state.iteration

    residual = jit(_residual, static_argnums=0)
    return lm, project, residual
