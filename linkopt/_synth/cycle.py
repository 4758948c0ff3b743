"""The dense cycle sweep of a synthesised design: every defect classic synthesis
leaves, found on the whole motion rather than at the precision points.

:func:`sweep_cycle` drives the motors along the design's cycle by continuation
(:func:`linkopt.solve_fk_path`: one jitted scan, each step predicted from the last
state and corrected, never allowed onto another assembly) and reads off

* a lost assembly: a step the branch of the rest pose cannot reach (a crank that
  cannot turn fully stops at its limit angle) -- a branch (circuit) defect;
* a state jump: a step whose state changes faster (per unit of motor change,
  homogenised) than ``JUMP_FACTOR`` times the median step's, or a closed turn that
  does not end where it began;
* a singularity: ``σ_min`` of the forward Jacobian ``∂C_FK/∂s`` below ``1/α₋``
  (eq. 3: ``f_sing < α₋`` needs each term below ``α₋``); a dead centre, where the
  motor no longer fixes the state. The backward Jacobian's ``σ_min`` is not judged:
  every scalar output of a closed cycle has a largest and a least value, where
  ``∂C_BK/∂s`` is singular, so a motor-driven cycle meets it by construction
  (:attr:`CycleReport.least_sigma` is the forward one);
* a target farther than its tolerance from the traced quantity, or the targets
  passed out of their order (cyclically for a closed curve);
* a collision: least clearance below the ``[collision]`` band.

Distances: a path target by Euclidean distance (file units), from the nearest step
refined to the straight segments on either side of it; a function target by
``|output − value|``; a motion target (pose) by ``max(position distance, rotation
angle)``, the angle ``2 atan2(|v|, |w|)`` of the relative quaternion in radians, so
that one ``tolerance`` bounds both (file units for the position, radians for the
angle). A timed target is judged at its own motor values.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from .._design.evaluation import alpha_minus
from .._engine.collision import clearance, has_collision
from .._engine.geometry import design_array
from .._engine.kinematics import solve_fk_path
from .._engine.model import Mechanism
from .._engine.singularity import singular_values
from .._errors import InputError
from .sweep import SweptRows, swept_rows, traced_quantity

#: A step whose rate of state change (per motor change) exceeds this multiple of the
#: median step's is a jump.
#: Our choice: a crank-rocker's fastest phase moves about 3x its median rate; a
#: jump to the other assembly of a four-bar moves the coupler by its whole span.
JUMP_FACTOR = 10.0
#: Closed sweeps: the state after a full turn matches the first to this (homogenised).
CLOSURE_TOLERANCE = 1e-6


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
    passed_at: np.ndarray  # (k,) step of each target: its timed step, else the nearest
    distances: np.ndarray  # (k,) distance to each target there
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
    -1 turns it the other way); one-DOF open, ``steps`` values over the motor's span
    (its limits, else the span of ``targets.motors``, else ``span``, which may run
    downwards); with timing, the timing values are swept
    exactly (one-DOF: inserted into that grid; multi-motor: piecewise linear through
    the timing rows, closed back to the first); multi-motor without timing, straight
    segments between the motor values that reach consecutive targets (Gauss–Newton
    on the motors). ``InputError`` naming the argument when the target's name is not
    the mechanism's or the motion cannot be made."""
    design = design_array(mech, design)[: mech.design.size]
    _check(mech, targets, steps)
    if direction not in (1, -1):
        raise InputError(f"direction: expected 1 or -1, got {direction!r}")
    rows = swept_rows(mech, design, targets, steps, span, direction)
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
# What the sweep traced, and the report


def _report(mech, design, targets, sweep: SweptRows, solution) -> CycleReport:
    """:class:`CycleReport` of the swept states (a closing row is left out)."""
    states = np.asarray(solution.state)
    solved = np.asarray(solution.converged, dtype=bool)
    rows, count = sweep.motors, len(sweep.motors) - int(sweep.closing)
    values = np.asarray(targets.values, dtype=float)
    traced = np.asarray(traced_quantity(mech, design, targets, states[:count]))
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
    moved = np.max(np.abs(np.diff(rows, axis=0)) / mech.motor_scale, axis=1)
    jumped = jump_steps(solved, jumps, moved)
    troubled = (sigma < bound) | jumped
    found, lost = [], np.flatnonzero(~solved)
    if len(lost):
        end = first = int(lost[0])
        while first > 0 and troubled[first - 1]:
            first -= 1
        troubled[first:end] = False
        found.append((first, 0, _lost(rows, first, end)))
    for i in np.flatnonzero(troubled & jumped)[:1]:
        found.append((int(i), 1, _jump_line(rows, jumps, moved, solved, int(i))))
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


def jump_steps(solved: np.ndarray, jumps: np.ndarray, moved: np.ndarray) -> np.ndarray:
    """Steps ``(s,)`` into which the state changes faster than ``JUMP_FACTOR`` times
    the median rate, between two solved steps: ``jumps (s-1,)`` the state changes,
    ``moved (s-1,)`` the motor changes (homogenised); a state change with no motor
    change is a jump."""
    rate = _rates(jumps, moved)
    both = solved[1:] & solved[:-1]
    out = np.zeros(len(solved), dtype=bool)
    if np.any(both):
        out[1:] = both & (rate > _rate_limit(rate[both]))
    return out


def _rates(jumps: np.ndarray, moved: np.ndarray) -> np.ndarray:
    still = np.where(jumps > CLOSURE_TOLERANCE, np.inf, 0.0)
    return np.where(moved > 0, jumps / np.maximum(moved, 1e-300), still)


def _rate_limit(rates: np.ndarray) -> float:
    finite = rates[np.isfinite(rates)]
    return JUMP_FACTOR * float(np.median(finite) if len(finite) else 0.0) + 1e-12


def _jump_line(rows, jumps, moved, solved, i: int) -> str:
    rate = _rates(jumps, moved)
    both = solved[1:] & solved[:-1]
    ratio = rate[i - 1] / (_rate_limit(rate[both]) / JUMP_FACTOR)
    return (
        f"state jump (branch change) of {jumps[i - 1]:.3g} into {_motor(rows, i)}, "
        f"{ratio:.3g} times the median rate"
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
