"""The dense cycle sweep of a synthesised design: every defect classic synthesis
leaves, found on the whole motion rather than at the precision points.

:func:`sweep_cycle` drives the motors along the design's cycle by continuation
(:func:`linkopt.solve_fk_path`: one jitted scan, each step predicted from the last
state and corrected, never allowed onto another assembly) and reads off

* a lost assembly: a step the branch of the rest pose cannot reach (a crank that
  cannot turn fully stops at its limit angle) -- a branch (circuit) defect;
* a state jump: a step whose state change exceeds ``JUMP_FACTOR`` times the median
  step's (homogenised units), or a closed turn that does not end where it began;
* a singularity: ``σ_min`` of the forward Jacobian ``∂C_FK/∂s`` below ``1/α₋``
  (eq. 3: ``f_sing < α₋`` needs each term below ``α₋``); a dead centre, where the
  motor no longer fixes the state. The backward Jacobian's ``σ_min`` is not judged:
  every scalar output of a closed cycle has a largest and a least value, where
  ``∂C_BK/∂s`` is singular, so a motor-driven cycle meets it by construction
  (:attr:`CycleReport.least_sigma` is the forward one);
* a target farther than its tolerance from the traced quantity, or the targets
  passed out of their order (cyclically for a closed curve);
* a collision: least clearance below the ``[collision]`` band.

Distances: a path target by Euclidean distance (file units); a function target by
``|output − value|``; a motion target (pose) by ``max(position distance, rotation
angle)``, the angle ``2 acos |q · q_t|`` in radians, so that one ``tolerance`` bounds
both (file units for the position, radians for the angle).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from .._design.evaluation import alpha_minus
from .._engine.collision import clearance, has_collision
from .._engine.geometry import design_array, rest_state
from .._engine.kinematics import solve_fk_path
from .._engine.model import Mechanism
from .._engine.readout import (
    motor_values,
    output_values,
    point_positions,
    reported_values,
)
from .._engine.singularity import singular_values
from .._errors import InputError

#: A step whose state change exceeds this multiple of the median step's is a jump.
#: Our choice: a crank-rocker's fastest phase moves about 3x its median rate; a
#: jump to the other assembly of a four-bar moves the coupler by its whole span.
JUMP_FACTOR = 10.0
#: Closed sweeps: the state after a full turn matches the first to this (homogenised).
CLOSURE_TOLERANCE = 1e-6
#: Rows of a multi-motor sweep without timing: Gauss–Newton iterations per target.
IK_ITERATIONS = 30
#: ... and the target's error (file units; quaternion components) that ends them.
IK_TOLERANCE = 1e-10


@dataclass(frozen=True)
class CycleReport:
    """The dense sweep of one design over its cycle (module docstring).

    ``traced`` rows have the layout of :attr:`Targets.values` rows: path ``(s, 3)``,
    function ``(s,)``, motion ``(s, 7)``. Unsolved steps' rows are NaN.
    """

    motors: np.ndarray  # (s, n_motors) the motor values swept, in order (file units)
    traced: np.ndarray  # (s, ...) the traced quantity, as Targets.values rows
    solved: np.ndarray  # (s,) bool
    largest_jump: float  # largest state change between consecutive steps
    largest_residual: float
    least_sigma: float  # least forward σ_min over the solved steps
    alpha_minus: float
    passed_at: np.ndarray  # (k,) step index at which each target is nearest
    distances: np.ndarray  # (k,) nearest distance to each target
    in_order: bool
    least_clearance: float | None
    defect: str | None


def sweep_cycle(
    mech: Mechanism,
    design,
    targets,
    *,
    steps: int = 360,
    span: tuple[float, float] | None = None,
    direction: int = 1,
) -> CycleReport:
    """Sweep ``design`` (None: the file's) over its cycle and judge it against
    ``targets`` (a :class:`linkopt._synth.targets.Targets`).

    The motion: one-DOF closed, the motor through one full turn from its rest value
    (``steps`` steps, plus one closing step checked against the start; ``direction``
    -1 turns it the other way); one-DOF open,
    ``steps`` values over the motor's span (its limits, else the span of
    ``targets.motors``, else ``span``); with timing, the timing values are swept
    exactly (one-DOF: inserted into that grid; multi-motor: piecewise linear through
    the timing rows, closed back to the first); multi-motor without timing, straight
    segments between the motor values that reach consecutive targets (Gauss–Newton
    on the motors). ``InputError`` naming the argument when the target's name is not
    the mechanism's or the motion cannot be made."""
    design = design_array(mech, design)[: mech.design.size]
    _check(mech, targets, steps)
    if direction not in (1, -1):
        raise InputError(f"direction: expected 1 or -1, got {direction!r}")
    rows = _sweep_rows(mech, design, targets, steps, span, direction)
    solution = solve_fk_path(mech, rows.motors, design=design)
    return _report(mech, design, targets, rows, solution)


# ---------------------------------------------------------------------------------
# Argument checks


def _check(mech: Mechanism, targets, steps: int) -> None:
    if not isinstance(steps, (int, np.integer)) or steps < 2:
        raise InputError(f"steps: expected an integer of at least 2, got {steps!r}")
    kinds = {"path": _point_names, "function": _output_names, "motion": _body_names}
    if targets.kind not in kinds:
        raise InputError(
            f"targets.kind: expected path, function or motion, got {targets.kind!r}"
        )
    names = kinds[targets.kind](mech)
    if targets.name not in names:
        raise InputError(
            f"targets.name: {targets.name!r} is not a {targets.kind} name of "
            f"{mech.source} (expected one of {', '.join(names) or 'none'})"
        )
    if targets.motors is not None and np.shape(targets.motors)[1:] != (
        mech.num_motors,
    ):
        raise InputError(
            f"targets.motors: expected (k, {mech.num_motors}) motor values, got "
            f"{np.shape(targets.motors)}"
        )


def _point_names(mech: Mechanism) -> tuple[str, ...]:
    return mech.point_names


def _output_names(mech: Mechanism) -> tuple[str, ...]:
    reported = mech.reported.names if mech.reported is not None else ()
    return mech.output_names + reported


def _body_names(mech: Mechanism) -> tuple[str, ...]:
    return tuple(n for i, n in enumerate(mech.body_names) if i != mech.ground)


# ---------------------------------------------------------------------------------
# The motor values swept


@dataclass(frozen=True)
class _Rows:
    """The motor rows swept ``(s, M)`` (file units); whether the last closes a full
    turn (left out of the report); the row of each timed target, or None."""

    motors: np.ndarray
    closing: bool
    timed: np.ndarray | None


def _sweep_rows(mech, design, targets, steps, span, direction) -> _Rows:
    rest = np.asarray(motor_values(mech, rest_state(mech), design=design))
    timing = None if targets.motors is None else np.asarray(targets.motors, float)
    if mech.num_motors == 1:
        turn = 2.0 * np.pi * direction
        return _one_motor_rows(mech, targets, rest[0], timing, steps, span, turn)
    if timing is None:
        timing = _reaching_motors(mech, design, targets, rest)
    rows, timed = _piecewise(timing, steps, targets.closed)
    return _Rows(rows, targets.closed, timed)


def _one_motor_rows(mech, targets, rest, timing, steps, span, turn) -> _Rows:
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
        return _Rows(grid[:, None], True, _rows_of(grid, timed))
    low, high = _open_span(mech, timing, span)
    grid = np.linspace(low, high, steps)
    if timing is not None:
        grid = np.union1d(grid, timing[:, 0])
    return _Rows(grid[:, None], False, _rows_of(grid, timing))


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
                return _read(mech, design, targets, s[None])[0]

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


# ---------------------------------------------------------------------------------
# What the sweep traced, and the report


def _read(mech, design, targets, states):
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


def _report(mech, design, targets, sweep: _Rows, solution) -> CycleReport:
    """:class:`CycleReport` of the swept states (a closing row is left out)."""
    states = np.asarray(solution.state)
    solved = np.asarray(solution.converged, dtype=bool)
    rows, count = sweep.motors, len(sweep.motors) - int(sweep.closing)
    values = np.asarray(targets.values, dtype=float)
    traced = np.asarray(_read(mech, design, targets, states[:count]))
    traced = np.where(_rows_like(solved[:count], traced), traced, np.nan)
    passed_at, distances = _nearest(targets, traced, values, sweep.timed)
    jumps = np.max(np.abs(np.diff(states, axis=0)), axis=1)
    sigma = _forward_sigmas(mech, design, states, solved)
    gaps = _clearances(mech, design, states, solved)
    least_clearance = None if gaps is None else float(np.min(gaps, initial=np.inf))
    alpha = alpha_minus(mech)
    residuals = np.asarray(solution.residual)[solved]
    report = CycleReport(
        motors=rows[:count],
        traced=traced,
        solved=solved[:count],
        largest_jump=float(np.max(jumps, initial=0.0)),
        largest_residual=float(np.max(residuals)) if len(residuals) else np.nan,
        least_sigma=float(np.min(sigma, initial=np.inf)),
        alpha_minus=alpha,
        passed_at=passed_at,
        distances=distances,
        in_order=in_order(passed_at, targets.closed),
        least_clearance=least_clearance,
        defect=None,
    )
    found = _defects(mech, targets, report, (rows, states, solved, jumps, sigma, gaps))
    return replace(report, defect=min(found)[2] if found else None)


def _rows_like(mask: np.ndarray, traced: np.ndarray) -> np.ndarray:
    return mask.reshape(mask.shape + (1,) * (traced.ndim - 1))


def _forward_sigmas(mech, design, states, solved) -> np.ndarray:
    """Forward ``σ_min`` of each step (``inf`` where unsolved)."""
    sigma = np.full(len(states), np.inf)
    if np.any(solved):
        pairs = np.asarray(singular_values(mech, states[solved], design=design))
        sigma[solved] = pairs[:, 0]
    return sigma


def _clearances(mech, design, states, solved) -> np.ndarray | None:
    """Least clearance of each step (file units; ``inf`` where unsolved), None
    without ``[collision]``."""
    if not has_collision(mech):
        return None
    gaps = np.full(len(states), np.inf)
    if np.any(solved):
        gaps[solved] = clearance(mech, states[solved], design=design).minimum
    return gaps


def _motor(rows: np.ndarray, step: int) -> str:
    values = ", ".join(f"{v:.6g}" for v in rows[min(step, len(rows) - 1)])
    return f"step {step}, motor {values}"


def _defects(mech, targets, report: CycleReport, sweep) -> list[tuple]:
    """Every defect found, as ``(step, rank, one line)``; the first by step (then
    rank) is the report's. The singular or jumping steps that lead straight into a
    lost assembly (a crank nearing its limit angle) are reported as that loss."""
    rows, states, solved, jumps, sigma, gaps = sweep
    bound = 1.0 / report.alpha_minus
    jumped = _jumped(solved, jumps)
    troubled = (sigma < bound) | jumped
    found, lost = [], np.flatnonzero(~solved)
    if len(lost):
        end = first = int(lost[0])
        while first > 0 and troubled[first - 1]:
            first -= 1
        troubled[first:end] = False
        found.append((first, 0, _lost(rows, first, end)))
    for i in np.flatnonzero(troubled & jumped)[:1]:
        found.append((int(i), 1, _jump_line(rows, jumps, solved, int(i))))
    for i in np.flatnonzero(troubled & (sigma < bound))[:1]:
        found.append(
            (
                int(i),
                2,
                f"singularity at {_motor(rows, i)}: forward σ_min "
                f"{sigma[i]:.3g} below 1/α₋ = {bound:.3g}",
            )
        )
    found += _closure(rows, states, solved, len(report.motors))
    found += _collisions(mech, rows, gaps)
    return found + _target_defects(targets, report, rows)


def _lost(rows, first: int, end: int) -> str:
    line = (
        f"lost assembly (branch defect) at {_motor(rows, end)}: the rest pose's "
        "branch does not reach it"
    )
    if first < end:
        line += f" (singular or jumping from step {first} on)"
    return line


def _jumped(solved: np.ndarray, jumps: np.ndarray) -> np.ndarray:
    """Steps (into which) the state changes by more than ``JUMP_FACTOR`` times the
    median step, between two solved steps."""
    both = solved[1:] & solved[:-1]
    out = np.zeros(len(solved), dtype=bool)
    if np.any(both):
        out[1:] = both & (jumps > _jump_limit(solved, jumps))
    return out


def _jump_limit(solved: np.ndarray, jumps: np.ndarray) -> float:
    both = solved[1:] & solved[:-1]
    return JUMP_FACTOR * float(np.median(jumps[both])) + CLOSURE_TOLERANCE


def _jump_line(rows, jumps, solved, i: int) -> str:
    ratio = jumps[i - 1] / _jump_limit(solved, jumps) * JUMP_FACTOR
    return (
        f"state jump (branch change) of {jumps[i - 1]:.3g} into {_motor(rows, i)}, "
        f"{ratio:.3g} times the median step"
    )


def _closure(rows, states, solved, count: int) -> list[tuple]:
    """A full turn that does not end where it began."""
    if len(states) == count or not (solved[-1] and solved[0]):
        return []
    gap = _closure_gap(states[0], states[-1])
    if gap <= CLOSURE_TOLERANCE:
        return []
    line = (
        f"the full turn ends on another assembly at {_motor(rows, count)}: its "
        f"state is {gap:.3g} from the start"
    )
    return [(count, 1, line)]


def _collisions(mech, rows, gaps) -> list[tuple]:
    if gaps is None:
        return []
    band = mech.collision.clearance
    hit = np.flatnonzero(gaps < band)[:1]
    return [
        (
            int(i),
            3,
            f"collision at {_motor(rows, i)}: clearance {gaps[i]:.4g} below the "
            f"band {band:g}",
        )
        for i in hit
    ]


def _closure_gap(first: np.ndarray, last: np.ndarray) -> float:
    """State distance after a full turn, each body's quaternion up to its sign (a body
    turned once has ``-q``)."""
    a, b = first.reshape(-1, 7), last.reshape(-1, 7)
    position = np.max(np.abs(a[:, :3] - b[:, :3]), initial=0.0)
    quat = np.minimum(np.abs(a[:, 3:] - b[:, 3:]), np.abs(a[:, 3:] + b[:, 3:]))
    return float(max(position, np.max(quat, initial=0.0)))


def _target_defects(targets, report: CycleReport, rows) -> list[tuple]:
    """Targets farther than the tolerance, and targets passed out of order."""
    found = []
    for j in np.flatnonzero(report.distances > targets.tolerance):
        i = int(report.passed_at[j])
        found.append(
            (
                i,
                4,
                f"target {j} not reached: {report.distances[j]:.4g} from "
                f"the traced {targets.kind} (nearest at {_motor(rows, i)}), "
                f"beyond the tolerance {targets.tolerance:g}",
            )
        )
    descents = _descents(report.passed_at, targets.closed)
    if len(descents) > int(targets.closed):
        p = report.passed_at
        j = min(descents, key=lambda d: p[d % len(p)])
        j, before = j % len(p), (j - 1) % len(p)
        found.append(
            (
                int(p[j]),
                5,
                f"targets out of order: target {j} is passed at "
                f"{_motor(rows, int(p[j]))}, target {before} only at step "
                f"{int(p[before])}",
            )
        )
    return found


def _nearest(targets, traced, values, timed):
    """The step of each target (its timed row, else the nearest) and the distance
    there; without timing, a path or function target's distance is refined to the
    straight segments on either side of that step."""
    near = distances_to(targets.kind, traced, values)
    near = np.where(np.isnan(near), np.inf, near)
    passed_at = np.argmin(near, axis=0) if timed is None else np.asarray(timed)
    distances = near[passed_at, np.arange(len(values))]
    if timed is not None or targets.kind == "motion":
        return passed_at, distances
    rows = traced.reshape(len(traced), -1)
    for j, (i, target) in enumerate(zip(passed_at, values.reshape(len(values), -1))):
        for k in (i - 1, i + 1):
            k = k % len(rows) if targets.closed else k
            if 0 <= k < len(rows):
                distances[j] = min(distances[j], _to_segment(rows[i], rows[k], target))
    return passed_at, distances


def _to_segment(p: np.ndarray, q: np.ndarray, x: np.ndarray) -> float:
    """Distance from ``x`` to the segment ``p q`` (inf when either end is NaN)."""
    span = q - p
    if not np.all(np.isfinite(span)):
        return float("inf")
    t = np.clip(np.dot(x - p, span) / max(float(np.dot(span, span)), 1e-300), 0, 1)
    return float(np.linalg.norm(p + t * span - x))


def distances_to(kind: str, traced: np.ndarray, values: np.ndarray) -> np.ndarray:
    """Distance ``(s, k)`` of each traced row to each target (module docstring)."""
    if kind == "function":
        return np.abs(traced[:, None] - values[None, :])
    position = np.linalg.norm(traced[:, None, :3] - values[None, :, :3], axis=-1)
    if kind == "path":
        return position
    return np.maximum(
        position, rotation_angle(traced[:, None, 3:], values[None, :, 3:])
    )


def rotation_angle(q: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Angle (rad, in ``[0, π]``) of the rotation between unit quaternions ``q`` and
    ``t`` (``wxyz``, broadcast): ``2 atan2(|v|, |w|)`` of ``t̄ q``, accurate near zero
    (``acos`` of the dot product loses half the digits there)."""
    w = np.sum(q * t, axis=-1)
    v = t[..., :1] * q[..., 1:] - q[..., :1] * t[..., 1:]
    v = v - np.cross(t[..., 1:], q[..., 1:])
    return 2.0 * np.arctan2(np.linalg.norm(v, axis=-1), np.abs(w))


def in_order(passed_at: np.ndarray, closed: bool) -> bool:
    """Whether the steps at which the targets are passed never decrease (closed: at
    most once, where the cycle wraps)."""
    return len(_descents(passed_at, closed)) <= int(closed)


def _descents(passed_at: np.ndarray, closed: bool) -> list[int]:
    """Indices ``i`` of the targets passed before the one listed ahead of them."""
    p = np.asarray(passed_at)
    following = np.roll(p, -1) if closed else np.append(p[1:], np.iinfo(int).max)
    return [i + 1 for i in np.flatnonzero(following < p)]
