"""What a cycle sweep (:mod:`.cycle`) drives and reads: the motor rows of a design's
cycle, and the traced quantity (a point's position, an output, a body's pose) of its
states, in file units."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .._engine.geometry import rest_state
from .._engine.readout import (
    motor_values,
    output_values,
    point_positions,
    reported_values,
)
from .._errors import InputError

#: Rows of a multi-motor sweep without timing: Gauss–Newton iterations per target.
IK_ITERATIONS = 30
#: ... and the target's error (file units; quaternion components) that ends them.
IK_TOLERANCE = 1e-10


@dataclass(frozen=True)
class SweptRows:
    """The motor rows swept ``(s, M)`` (file units); whether the last closes a full
    turn (left out of the report); the row of each timed target, or None."""

    motors: np.ndarray
    closing: bool
    timed: np.ndarray | None


def swept_rows(mech, design, targets, steps, span, direction) -> SweptRows:
    """The motor rows of ``design``'s cycle for ``targets``
    (:func:`linkopt._synth.cycle.sweep_cycle` says which)."""
    rest = np.asarray(motor_values(mech, rest_state(mech), design=design))
    timing = None if targets.motors is None else np.asarray(targets.motors, float)
    if mech.num_motors == 1:
        turn = 2.0 * np.pi * direction
        return _one_motor_rows(mech, targets, rest[0], timing, steps, span, turn)
    if timing is None:
        timing = _reaching_motors(mech, design, targets, rest)
    rows, timed = _piecewise(timing, steps, targets.closed)
    return SweptRows(rows, targets.closed, timed)


def _one_motor_rows(mech, targets, rest, timing, steps, span, turn) -> SweptRows:
    if targets.closed:
        if mech.motor_linear[0]:
            raise InputError(
                f"targets.closed: a closed curve needs a rotary motor; "
                f"{mech.motor_names[0]} of {mech.source} is linear"
            )
        grid = rest + turn * np.arange(steps + 1) / steps
        timed = None
        if timing is not None:
            timed = rest + np.sign(turn) * np.mod(
                np.sign(turn) * (timing[:, 0] - rest), 2.0 * np.pi
            )
            grid = np.union1d(grid[:-1], timed)[:: int(np.sign(turn))]
            grid = np.append(grid, rest + turn)
        return SweptRows(grid[:, None], True, _rows_of(grid, timed))
    low, high = _open_span(mech, timing, span)
    grid = np.linspace(low, high, steps)
    if timing is not None:
        grid = np.union1d(grid, timing[:, 0])
    return SweptRows(grid[:, None], False, _rows_of(grid, timing))


def _rows_of(grid: np.ndarray, values) -> np.ndarray | None:
    if values is None:
        return None
    return np.array([int(np.argmin(np.abs(grid - v))) for v in np.ravel(values)])


def _open_span(mech, timing, span) -> tuple[float, float]:
    """The one motor's span for an open sweep (see :func:`sweep_cycle`)."""
    limits = (mech.motor_min, mech.motor_max)
    if limits[0] is not None and np.all(np.isfinite([limits[0][0], limits[1][0]])):
        low, high = float(limits[0][0]), float(limits[1][0])
    elif timing is not None and np.ptp(timing[:, 0]) > 0:
        low, high = float(np.min(timing)), float(np.max(timing))
    elif span is not None:
        low, high = (float(v) for v in span)
    else:
        raise InputError(
            f"span: an open sweep of {mech.source} needs the motor's limits, timing "
            "or a span (low, high)"
        )
    if timing is not None and (np.min(timing) < low or np.max(timing) > high):
        raise InputError(
            f"targets.motors: timing values outside the swept span [{low:g}, {high:g}]"
        )
    return low, high


def _piecewise(rows: np.ndarray, steps: int, closed: bool):
    """Piecewise-linear motor rows through ``rows`` (each kept exactly), about
    ``steps`` in all, spread by segment length; closed: back to the first row. Also
    the index of each of ``rows`` in them."""
    corners = np.concatenate([rows, rows[:1]]) if closed else rows
    lengths = np.linalg.norm(np.diff(corners, axis=0), axis=1)
    total = max(float(np.sum(lengths)), 1e-300)
    pieces, timed = [corners[:1]], [0]
    for start, end, length in zip(corners[:-1], corners[1:], lengths):
        count = max(1, int(round(steps * length / total)))
        t = np.arange(1, count + 1)[:, None] / count
        pieces.append(start + t * (end - start))
        timed.append(timed[-1] + count)
    return np.concatenate(pieces), np.array(timed[: len(rows)])


def reaching_timing(mech, design, targets) -> np.ndarray:
    """Motor values ``(k, M)`` (file units) at which ``design`` reaches each target of
    a multi-motor target without timing, in turn from the rest pose, held inside the
    motors' limits: the timing a synthesis run fits its designs at
    (:func:`linkopt._synth.run.synthesize`). A target out of the design's reach gets
    the motor values nearest to it in the least-squares sense."""
    rest = np.asarray(motor_values(mech, rest_state(mech), design=design))
    motors = _reaching_motors(mech, design, targets, rest)
    if mech.motor_limited:
        motors = np.clip(motors, mech.motor_min, mech.motor_max)
    return motors


def _reaching_motors(mech, design, targets, rest) -> np.ndarray:
    """Motor values ``(k, M)`` that reach each target in turn (damped Gauss–Newton on
    the motors, each target started from the last; the Jacobian by the implicit
    function theorem through :func:`linkopt.solve_fk`)."""
    import jax

    from .._engine.kinematics import solve_fk

    if targets.kind == "function":
        raise InputError(
            f"targets.kind: a function target needs a one-motor mechanism; "
            f"{mech.source} has {mech.num_motors}"
        )
    state = np.asarray(rest_state(mech))
    motors, found = np.asarray(rest, float), []
    for target in np.asarray(targets.values, float):
        for _ in range(IK_ITERATIONS):

            def trace(a, start=state):
                s = solve_fk(mech, a, start=start, design=design).state
                return traced_quantity(mech, design, targets, s[None])[0]

            error = _residual(targets.kind, np.asarray(trace(motors)), target)
            if np.max(np.abs(error)) < IK_TOLERANCE:
                break
            jac = np.asarray(jax.jacfwd(trace)(motors))
            step = np.linalg.lstsq(jac, -error, rcond=None)[0]
            motors = motors + np.clip(step, -0.2, 0.2)
            state = np.asarray(solve_fk(mech, motors, start=state, design=design).state)
        found.append(motors.copy())
    return np.array(found)


def _residual(kind: str, value: np.ndarray, target: np.ndarray) -> np.ndarray:
    """What Gauss–Newton drives to zero: the position error of a path target, the
    position and quaternion error (sign-aligned) of a motion target."""
    if kind == "motion":
        sign = 1.0 if np.dot(value[3:], target[3:]) >= 0 else -1.0
        return np.concatenate([value[:3] - target[:3], sign * value[3:] - target[3:]])
    return value - target


def traced_quantity(mech, design, targets, states):
    """The traced quantity of states ``(N, S)`` in file units; traceable in the
    states (the IK's Jacobian), JAX arrays then."""
    import jax.numpy as jnp

    if targets.kind == "path":
        index = mech.point_names.index(targets.name)
        return point_positions(mech, states, design=design)[:, index]
    if targets.kind == "function" and targets.name in mech.output_names:
        values = output_values(mech, states, design=design)
        return values[:, mech.output_names.index(targets.name)]
    if targets.kind == "function":
        values = reported_values(mech, states, design=design)
        return values[:, mech.reported.names.index(targets.name)]
    body = mech.body_names.index(targets.name)
    pose = states[:, 7 * body : 7 * body + 7]
    return jnp.concatenate([pose[:, :3] * mech.length_scale, pose[:, 3:]], axis=1)
