"""Synthesis targets (the synthesis contract's :class:`Targets`) and the checks that
need the mechanism: which motion the targets ask of its motors, and whether its
design bounds can reach them at all.

The reader of the ``[synthesis]`` table and of target CSVs is
:mod:`linkopt._files.synthesis` (every table reader lives in ``_files``); this module
adds what needs the mechanism's geometry, before any solve:

* a function target needs a one-motor mechanism;
* timing rows give one value per motor, inside the motors' limits;
* a closed curve needs one rotary motor whose limits (if any) allow a full turn. This
  is what is checked before any work; whether the design bounds hold a design whose
  crank turns fully is found by the sweep itself (a design that cannot turn fully
  fails its sweep and scores the penalty of :mod:`.objective`);
* a multi-motor target without timing is met through the motor values that reach
  each target (:func:`linkopt._synth.sweep.reaching_timing`), so it needs a path or
  motion target;
* every path or motion target lies within reach: a cheap bound, :func:`reach_bound`.
"""

from __future__ import annotations

import itertools
from pathlib import Path

import numpy as np

from .._engine.following import rest_points
from .._engine.model import Mechanism
from .._errors import MechanismFileError
from .._files.synthesis import (
    Targets,
    build,
    read_rows,
    read_synthesis,
    synthesis_names,
)

__all__ = ["Targets", "check_targets", "load_targets", "reach_bound", "targets_of"]

#: Design parameters up to which every corner of the design box is tried by
#: :func:`reach_bound`; above it, this many random corners (seed 0).
ALL_CORNERS = 12
FULL_TURN = 2.0 * np.pi


def targets_of(mech: Mechanism) -> Targets:
    """The targets of the file's ``[synthesis]`` table, checked
    (:func:`check_targets`)."""
    if "synthesis" not in mech.raw:
        raise MechanismFileError(
            mech.source, "[synthesis]", "missing table; the file has no target to meet"
        )
    targets = read_synthesis(mech.source, mech.raw["synthesis"], synthesis_names(mech))
    return check_targets(mech, targets)


def load_targets(mech: Mechanism, csv: str | Path | None = None) -> Targets:
    """The targets of ``mech``: those of its ``[synthesis]`` table, or, with ``csv``,
    the rows of that CSV file with the table's kind, name, closed and tolerance."""
    if csv is None:
        return targets_of(mech)
    table = read_synthesis(mech.source, _without_rows(mech), synthesis_names(mech))
    rows, motors = read_rows(Path(csv), table.kind, table.name, synthesis_names(mech))
    targets = build(
        str(csv), str(csv), table.kind, table.name, rows, motors,
        table.closed, table.tolerance, table.min_transmission_deg,
    )  # fmt: skip
    return check_targets(mech, targets)


def _without_rows(mech: Mechanism) -> dict:
    """The ``[synthesis]`` table with two dummy rows instead of its own points, so
    that a CSV's rows replace them."""
    if "synthesis" not in mech.raw:
        raise MechanismFileError(
            mech.source,
            "[synthesis]",
            "missing table; a targets CSV needs the table's kind, name and tolerance",
        )
    table = {k: v for k, v in mech.raw["synthesis"].items() if k not in ("file",)}
    width = {"path": 3, "function": 2, "motion": 7}.get(table.get("kind"), 3)
    dummy = [[float(k)] * width for k in range(3)]
    if table.get("kind") == "motion":
        dummy = [[float(k), 0, 0, 1, 0, 0, 0] for k in range(3)]
    table.pop("motors", None)
    return {**table, "points": dummy}


def check_targets(mech: Mechanism, targets: Targets) -> Targets:
    """``targets`` when ``mech`` can be asked to meet them (module docstring); else a
    :class:`MechanismFileError` naming the file and field."""
    at = targets.source or "[synthesis]"
    fail = lambda where, message: MechanismFileError(mech.source, where, message)  # noqa: E731
    if targets.kind == "function" and mech.num_motors != 1:
        raise fail(
            "[synthesis].kind",
            f"a function target needs a one-motor mechanism; this one has "
            f"{mech.num_motors} motors {list(mech.motor_names)}",
        )
    if targets.motors is not None:
        _check_timing(mech, targets, fail, at)
    if targets.closed:
        _check_crank(mech, fail)
    _check_body(mech, targets, fail)
    if targets.kind in ("path", "motion"):
        _check_reach(mech, targets, fail, at)
    return targets


def _check_timing(mech: Mechanism, targets: Targets, fail, at: str) -> None:
    motors = targets.motors
    if motors.shape[1] != mech.num_motors:
        raise fail(
            f"{at}",
            f"timing gives {motors.shape[1]} motor values per target; the mechanism "
            f"has {mech.num_motors} motors {list(mech.motor_names)}",
        )
    if not mech.motor_limited:
        return
    for m, name in enumerate(mech.motor_names):
        low, high = mech.motor_min[m], mech.motor_max[m]
        out = np.flatnonzero((motors[:, m] < low) | (motors[:, m] > high))
        if len(out):
            raise fail(
                f"{at}[{out[0]}]",
                f"timing value {motors[out[0], m]:.6g} of motor {name!r} is outside "
                f"its range [{low:.6g}, {high:.6g}] ([[motors]] min/max)",
            )


def _check_crank(mech: Mechanism, fail) -> None:
    where = "[synthesis].closed"
    if mech.num_motors != 1 or bool(mech.motor_linear[0]):
        raise fail(
            where,
            "a closed curve needs one rotary motor that turns fully (a crank); "
            f"this mechanism has motors {list(mech.motor_names)}"
            + (" (linear)" if mech.num_motors == 1 else ""),
        )
    if mech.motor_limited:
        span = float(mech.motor_max[0] - mech.motor_min[0])
        if span < FULL_TURN:
            raise fail(
                where,
                f"a closed curve needs a full turn of motor {mech.motor_names[0]!r}, "
                f"but its [[motors]] min/max allow {span:.6g} rad",
            )


def _check_body(mech: Mechanism, targets: Targets, fail) -> None:
    if targets.kind == "path":
        body = int(mech.point_bodies[mech.point_names.index(targets.name)])
    elif targets.kind == "motion":
        body = mech.body_names.index(targets.name)
    else:
        return
    if body == mech.ground:
        raise fail(
            "[synthesis].name",
            f"{targets.name!r} is on the ground body; it does not move",
        )


def _check_reach(mech: Mechanism, targets: Targets, fail, at: str) -> None:
    far, reach = reach_bound(mech, targets.values[:, :3])
    beyond = np.flatnonzero(far > reach + targets.tolerance)
    if len(beyond):
        k = int(beyond[0])
        raise fail(
            f"{at}[{k}]",
            f"target {np.round(targets.values[k, :3], 6).tolist()} is beyond any reach "
            f"of the design bounds: {far[k]:.6g} from the nearest ground joint, but no "
            f"design within the bounds reaches farther than {reach:.6g}",
        )


def _corners(mech: Mechanism) -> np.ndarray:
    d = mech.design
    n = d.size
    if n <= ALL_CORNERS:
        pick = np.array(list(itertools.product((0, 1), repeat=n)), dtype=bool)
    else:
        pick = np.random.default_rng(0).random((1 << ALL_CORNERS, n)) < 0.5
    pick = pick.reshape(-1, n)
    return np.where(pick, d.upper, d.lower).reshape(-1, n)


def _anchors_points(mech: Mechanism, p: np.ndarray):
    """Joint anchors and named points (file units) of design ``p``, the linear
    design map only (numpy)."""
    joints = mech.anchors.shape[0]
    change = mech.design.matrix[: 3 * joints] @ (p - mech.design.p0)
    anchors = mech.anchors + change.reshape(joints, 3)
    points = rest_points(mech, anchors, p - mech.design.p0)
    return anchors, np.asarray(points)


def _reach_at(mech: Mechanism, anchors, points) -> float:
    """The sum of the moving bodies' diameters (their joint anchors, named points and
    frame origins): no point of a body lies farther than it from a ground joint."""
    total = 0.0
    for b in range(mech.num_bodies):
        if b == mech.ground:
            continue
        on = np.any(mech.joint_bodies == b, axis=1)
        spots = np.concatenate(
            [anchors[on], points[mech.point_bodies == b], mech.body_origins[b : b + 1]]
        )
        gaps = np.linalg.norm(spots[:, None] - spots[None], axis=2)
        total += float(gaps.max())
    return total


def reach_bound(mech: Mechanism, where: np.ndarray) -> tuple[np.ndarray, float]:
    """``(far, reach)``: each position's least distance to a ground joint over the
    design box (at least the distance at the file's design less the joint's largest
    move), and the largest sum of body diameters over the box's corners. A position
    with ``far > reach`` is reached by no design within the bounds.

    For a linear design map both are bounds (a distance between anchors is convex in
    the design, so its largest value on the box is at a corner); with link angles
    (``kind = "twist"``) or more than :data:`ALL_CORNERS` parameters the corners are a
    sample and the bound an estimate."""
    grounded = np.flatnonzero(np.any(mech.joint_bodies == mech.ground, axis=1))
    anchors0 = mech.anchors[grounded]
    reach, moves = 0.0, np.zeros(len(grounded))
    for p in _corners(mech):
        anchors, points = _anchors_points(mech, p)
        reach = max(reach, _reach_at(mech, anchors, points))
        moves = np.maximum(moves, np.linalg.norm(anchors[grounded] - anchors0, axis=1))
    gaps = np.linalg.norm(where[:, None, :] - anchors0[None], axis=2) - moves[None]
    return gaps.min(axis=1), reach
