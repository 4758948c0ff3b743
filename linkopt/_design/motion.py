"""The frames of an animation: a mechanism along a path, solved by continuation (beyond
the paper; :mod:`linkopt._draw.animation` draws them as a GIF).

Path. A path is a sequence of motor rows (solved by forward kinematics) or of output
rows (backward kinematics), one row per frame, solved as one continuation path from the
rest pose (:func:`linkopt._engine.kinematics.solve_fk_path` / ``solve_bk_path``): each
row is reached from the previous one in predictor-corrector steps that are accepted
only when the corrector lands near the first-order prediction, so a frame is either on
the rest pose's assembly branch or reported unreached; that acceptance test is the
branch check here, as in every continuation of linkopt (a map's single warm-started
solves check a jump bound instead, :data:`linkopt._design.maps.MAX_JUMP`). The
continuation is a ``lax.scan`` over the rows: one compiled program per frame count,
whatever the design.

Default path (the issue leaves it open): a closed loop in output space through the
evaluation grid's targets (:func:`linkopt._design.evaluation.targets`), visited in the
order of a short closed tour (greedy nearest neighbour from the target nearest the rest
pose, then 2-opt, in coordinates scaled to the target box) and resampled to equal steps
of that scaled length; the last frame is one step before the first, so the GIF loops
without a repeated frame. A design that does not reach part of that loop is animated
along the loop pulled in towards its rest outputs where it is out of reach: each
unreached frame moves onto the straight line from the rest outputs to it, at
``PULL_IN`` of the way the rest branch reaches along that line (one batched
continuation from the rest pose, :func:`linkopt._engine.kinematics.solve_bk`), short of
the branch's limit, where the backward-kinematics Jacobian is singular and a
continuation cannot go on; the pulled-in loop is then solved again. So the animation
of a design that misses part of its box shows where it falls short. (We first ran such
loops through the design's IK samples, but a design evaluation made the run's
``motion_initial.gif`` cost several times the rest of the animation, and the IK,
solved in motor space, stops at forward singularities that backward kinematics passes.)
A frame still unreached is drawn where its continuation stopped and labelled "out of
reach". A path the caller gives is drawn only when every row is reached
(:class:`PathNotReached`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from jaxtyping import Bool, Float

from .._engine.arguments import check_design, check_values
from .._engine.geometry import rest_state
from .._engine.kinematics import (
    solve_bk,
    solve_bk_path,
    solve_fk_path,
)
from .._engine.model import Mechanism
from .._engine.readout import (
    joint_positions,
    motor_values,
    output_values,
    point_positions,
)
from .._engine.singularity import f_sing
from .._errors import InputError, LinkoptError
from .maps import check_count
from .settings import DEFAULT_FRAMES, MAX_FRAMES

#: Fraction of the rest branch's reach along the line from the rest outputs to which an
#: unreached frame of the default loop is pulled in (module docstring).
PULL_IN = 0.9


class PathNotReached(LinkoptError):
    """A frame of the path is not reached on the rest pose's assembly branch; ``row``
    is its 1-based index."""

    def __init__(self, message: str, row: int):
        super().__init__(message)
        self.row = row


@dataclass(frozen=True)
class Motion:
    """A mechanism along a path, one entry per frame (file units; states
    homogenised)."""

    kind: str  # "fk": the path is motor rows, "bk": output rows
    default: bool  # the default loop (drawn also where it is not reached)
    path: Float[np.ndarray, "T W"]
    states: Float[np.ndarray, "T S"]
    #: the row reached on the rest branch; an unreached frame holds the state where
    #: the continuation toward it stopped (the branch's limit on the way)
    reached: Bool[np.ndarray, " T"]
    progress: Float[np.ndarray, " T"]  # the continuation's progress into each row
    motors: Float[np.ndarray, "T M"]
    outputs: Float[np.ndarray, "T K"]
    joints: Float[np.ndarray, "T J 3"]
    points: Float[np.ndarray, "T P 3"]
    trace: Float[np.ndarray, "T Q 3"]  # the traced points (module docstring)
    trace_names: tuple[str, ...]
    f_sing: Float[np.ndarray, " T"]

    @property
    def first_unreached(self) -> int | None:
        """0-based index of the first unreached frame, None when all are reached."""
        missing = np.flatnonzero(~self.reached)
        return int(missing[0]) if len(missing) else None


# ---------------------------------------------------------------------------------
# The default path


def check_frames(frames, where: str = "frames") -> int:
    """``frames`` as an int in ``[1, MAX_FRAMES]``; :class:`InputError` otherwise."""
    frames = check_count(frames, where, 1)
    if frames > MAX_FRAMES:
        raise InputError(
            f"{where}: expected at most {MAX_FRAMES} frames, got {frames} (a GIF of "
            "more frames is too large to be useful)"
        )
    return frames


def _tour_length(points: np.ndarray, order: list[int]) -> float:
    ring = points[order + order[:1]]
    return float(np.sum(np.linalg.norm(np.diff(ring, axis=0), axis=1)))


def _greedy(points: np.ndarray, first: int) -> list[int]:
    """Nearest-neighbour tour from ``first``, ties to the lower index."""
    order, left = [first], set(range(len(points))) - {first}
    while left:
        rest = sorted(left)
        dist = np.linalg.norm(points[rest] - points[order[-1]], axis=1)
        order.append(rest[int(np.argmin(dist))])
        left.remove(order[-1])
    return order


def tour(points: Float[np.ndarray, "T K"], first: int = 0) -> list[int]:
    """A short closed tour through ``points`` starting at ``first``: greedy nearest
    neighbour, then 2-opt (segment reversals) while one shortens it by more than
    1e-12. Deterministic; a few dozen points (the evaluation's targets)."""
    order = _greedy(points, first)
    improved = True
    while improved:
        improved = False
        for i in range(1, len(order) - 1):
            for j in range(i + 1, len(order)):
                trial = order[:i] + order[i : j + 1][::-1] + order[j + 1 :]
                if _tour_length(points, trial) < _tour_length(points, order) - 1e-12:
                    order, improved = trial, True
    return order


def resample_loop(
    points: Float[np.ndarray, "T K"], frames: int, scale: np.ndarray
) -> Float[np.ndarray, "N K"]:
    """``frames`` points at equal steps of ``|Δ/scale|`` along the closed polygon
    through ``points``, from ``points[0]``, the last one step before it again."""
    ring = np.vstack([points, points[:1]])
    steps = np.linalg.norm(np.diff(ring, axis=0) / scale, axis=1)
    arc = np.concatenate([[0.0], np.cumsum(steps)])
    if arc[-1] <= 0.0:
        return np.repeat(points[:1], frames, axis=0)
    at = np.arange(frames) * arc[-1] / frames
    return np.stack(
        [np.interp(at, arc, ring[:, k]) for k in range(points.shape[1])], axis=1
    )


def default_path(
    mech: Mechanism, frames: int = DEFAULT_FRAMES, design=None
) -> Float[np.ndarray, "N K"]:
    """Output rows of the default loop through the targets (module docstring), file
    units."""
    from .evaluation import targets  # local: only the default path needs it

    frames = check_frames(frames)
    check_design(mech, design)
    goals = targets(mech)
    scale = np.maximum(mech.output_max - mech.output_min, 1e-12)
    rest = np.asarray(output_values(mech, rest_state(mech), design=design))
    first = int(np.argmin(np.linalg.norm((goals - rest) / scale, axis=1)))
    return resample_loop(goals[tour(goals / scale, first)], frames, scale)


# ---------------------------------------------------------------------------------
# Frames


def traced_points(mech: Mechanism) -> np.ndarray:
    """Indices of the traced points (module docstring)."""
    points = np.concatenate([mech.output_points, mech.reported_table.points])
    used = [int(p) for p in points if p >= 0]  # reported position outputs too
    if used:
        return np.array(sorted(set(used)), dtype=int)
    return np.arange(len(mech.point_names), dtype=int)


def motion(
    mech: Mechanism,
    *,
    design=None,
    frames: int = DEFAULT_FRAMES,
    motors=None,
    outputs=None,
    loop_of: Mechanism | None = None,
) -> Motion:
    """The frames of an animation: ``motors`` ``(T, M)`` or ``outputs`` ``(T, K)`` rows
    (file units, one frame each), or by default the loop of :func:`default_path` in
    ``frames`` frames. Every frame's solve, read-out and ``f_sing`` is one batched
    call; unreached frames are flagged in ``Motion.reached``, not raised.

    ``loop_of``: the mechanism whose targets the default loop goes through (default
    ``mech``), the same linkage as ``mech`` with other ``[evaluation]`` targets. An
    optimisation run animates its design along the loop through the run's targets
    (the file's and its verification rounds') but solves with the file's mechanism,
    whose compiled programs the initial design's animation has made: the targets are
    part of the mechanism's fingerprint, which keys every program."""
    check_design(mech, design)
    if loop_of is not None and loop_of.num_outputs != mech.num_outputs:
        raise InputError("motion: loop_of must have the outputs of the mechanism")
    kind, rows = _rows(loop_of or mech, design, frames, motors, outputs)
    solver = solve_fk_path if kind == "fk" else solve_bk_path
    solution = solver(mech, rows, design=design)
    default = motors is None and outputs is None
    if default and not np.all(solution.converged):
        rows = pulled_in(mech, rows, design)
        solution = solver(mech, rows, design=design)
    states = np.asarray(solution.state)
    reached = np.asarray(solution.converged)
    points = np.asarray(point_positions(mech, states, design=design))
    return Motion(
        kind=kind,
        default=default,
        path=rows,
        states=states,
        reached=reached,
        progress=np.asarray(solution.progress),
        motors=np.asarray(motor_values(mech, states, design=design)),
        outputs=np.asarray(output_values(mech, states, design=design)),
        joints=np.asarray(joint_positions(mech, states, design=design)),
        points=points,
        trace=points[:, traced_points(mech)],
        trace_names=tuple(mech.point_names[k] for k in traced_points(mech)),
        f_sing=np.asarray(f_sing(mech, states, design=design)),
    )


def pulled_in(
    mech: Mechanism, rows: Float[np.ndarray, "N K"], design
) -> Float[np.ndarray, "N K"]:
    """``rows`` with each one out of the rest branch's reach moved towards the rest
    outputs, to ``PULL_IN`` of the branch's reach along the line (module docstring)."""
    rest = np.asarray(output_values(mech, rest_state(mech), design=design))
    solution = solve_bk(mech, rows, design=design)
    fraction = np.where(
        solution.converged, 1.0, PULL_IN * np.asarray(solution.progress)
    )
    return rest + fraction[:, None] * (rows - rest)


def _rows(mech: Mechanism, design, frames, motors, outputs):
    """``(kind, rows)`` of the path (:func:`motion`)."""
    if motors is not None and outputs is not None:
        raise InputError("motion: give motors or outputs rows, not both")
    for kind, given in (("fk", motors), ("bk", outputs)):
        if given is not None:
            check_values(mech, kind, given, path=True)
            rows = np.asarray(given, dtype=np.float64)
            check_frames(len(rows), f"{'motors' if kind == 'fk' else 'outputs'} rows")
            return kind, rows
    return "bk", default_path(mech, frames, design)


def unreached_message(mech: Mechanism, item: Motion, what: str = "frame") -> str:
    """One line naming the first unreached frame (1-based, as ``what`` ``k``), its
    requested values and how far the continuation got from the frame before."""
    k = item.first_unreached
    names = mech.motor_names if item.kind == "fk" else mech.output_names
    values = ", ".join(f"{n}={v:.6g}" for n, v in zip(names, item.path[k]))
    origin = f"{what} {k}" if k > 0 else "the rest pose"
    solve = "FK" if item.kind == "fk" else "BK"
    return (
        f"{what} {k + 1} ({values}) is not reached on the rest pose's assembly branch: "
        f"the {solve} continuation stopped {100 * item.progress[k]:.0f} % of the way "
        f"from {origin} (no assembly past it on this branch, or a singularity)"
    )
