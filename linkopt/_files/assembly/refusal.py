"""Refusing a drawing whose loops do not close: which loop (its joints and bodies),
which dimensions cannot all hold, the gap, and which axes are held as written; and the
check of declared lengths in a file that is not assembled."""

from __future__ import annotations

import numpy as np

from ..fields import Reader
from .problem import Problem, Rows
from .solve import CLOSE_TOL, residual_np, solve, without_motors
from .write import fit, slide_values

#: An axis held as written on a body given by world anchors may turn this far (rad)
#: with the body's best-fit rotation before the assembly is refused.
HELD_AXIS_TOL = 1e-7
#: Declared lengths of a file that is not assembled hold to this (reference lengths).
CHECK_TOL = 1e-9


def refuse(rd: Reader, problem: Problem, x0, x) -> None:
    """The loops do not close from the drawing: say which loop, which dimensions and
    by how much, and which axes are held (module docstring); with motors held, first
    whether freeing them would close, and then what the motors would have to be."""
    free = without_motors(problem.rows)
    if len(problem.motor_names):
        y, residual, _ = solve(problem, x0, free)
        if residual <= CLOSE_TOL:
            raise rd.fail("[[motors]]", _motors_free(problem, x, y))
        x = y
    sizes = (len(problem.joint_names), len(problem.frame_names))
    r = residual_np(sizes, free, x)
    missing = _missing(r)
    rows = np.flatnonzero(missing)
    labels = [problem.row_labels[k] for k in rows]
    joints, bodies, count = _loop(problem, _joints_of(problem, rows))
    dims = _dimensions(problem, rows, r)
    raise rd.fail(
        labels[0][0] if labels else "[[lengths]]",
        f"the loop{'s' if count > 1 else ''} through joints "
        f"{', '.join(problem.joint_names[j] for j in joints)} (bodies "
        f"{', '.join(problem.body_names[b] for b in bodies)}) does not close: {dims} "
        f"cannot all hold; the closest assembly misses by {_gap(problem, r, missing)} "
        f"in all{_slides(problem, x, joints)}{_held_axes(problem, joints)}",
    )


def _missing(r: np.ndarray) -> np.ndarray:
    """The rows that miss: above 1e-3 of the largest miss (and the tolerance)."""
    return np.abs(r) > max(1e-3 * float(np.max(np.abs(r), initial=0.0)), CLOSE_TOL)


def _joints_of(problem: Problem, rows) -> list[int]:
    return sorted({j for k in rows for j in problem.row_joints[k]})


def _gap(problem: Problem, r: np.ndarray, missing: np.ndarray) -> str:
    """``'12.5 mm'``, and ``' and its axes by 0.3°'`` where axes miss."""
    gap, angle = _misses(r, missing, problem.rows)
    turned = f" and its axes by {angle:.3g}°" if angle > 0 else ""
    return f"{gap * problem.scale:.6g} {problem.units}{turned}"


def _motors_free(problem: Problem, x, y) -> str:
    """The message for loops that close only with the motors free: held, how far the
    closest assembly misses (its loop, and the motors' own share); free, where the
    nearest assembly to the drawing puts each motor (from the value held)."""
    sizes = (len(problem.joint_names), len(problem.frame_names))
    rows = problem.rows
    r = residual_np(sizes, rows, x)
    missing = _missing(r)
    count = len(rows.motor_target)
    missing[len(r) - count :] = False  # the motors' share is given apart
    joints, _, _ = _loop(problem, _joints_of(problem, np.flatnonzero(missing)))
    names = ", ".join(repr(name) for name in problem.motor_names)
    drives = ", ".join(
        f"{name!r} drives joint {problem.joint_names[j]}"
        for name, j in zip(problem.motor_names, rows.motor_joint)
    )
    held = _motor_offsets(problem, r[len(r) - count :], "off")
    free = _motor_offsets(
        problem, residual_np(sizes, rows, y)[len(r) - count :], "from the value held"
    )
    return (
        f"the loops close, but not with motor(s) {names} held at their drawn values "
        f"(plus --motors; {drives}): held there, the closest assembly misses by "
        f"{_gap(problem, r, missing)} in the loop through joints "
        f"{', '.join(problem.joint_names[j] for j in joints)}"
        f"{' and has ' + held if held else ''}; with them free, the assembly nearest "
        f"the drawing has {free or 'them where held'}{_slides(problem, y, joints)}: "
        "choose motor values the mechanism can reach, or draw it closer to an assembly"
    )


def _motor_offsets(problem: Problem, values, words: str) -> str:
    """``'lift' +3.2 mm off, 'crank' -0.1 rad (-5.7°) off``: the motors' rows (rad or
    reference lengths) where they are not zero."""
    items = []
    for name, v, linear in zip(problem.motor_names, values, problem.rows.motor_linear):
        if abs(v) <= CLOSE_TOL:
            continue
        if linear:
            items.append(f"{name!r} {v * problem.scale:+.6g} {problem.units} {words}")
        else:
            items.append(f"{name!r} {v:+.6g} rad ({np.degrees(v):+.4g}°) {words}")
    return ", ".join(items)


def _slides(problem: Problem, x, joints) -> str:
    """``; at that assembly cyl has slid -0.4 mm (rod along the axis from barrel)``
    for the loop's prismatic and cylindrical joints whose sliding bodies have frames:
    where the second body's anchor of each sits along the axis from the first's."""
    items = []
    for j, _, v in slide_values(problem, x):
        if j in joints:
            first, second = problem.pairs[j]
            items.append(
                f"{problem.joint_names[j]} has slid {v:+.6g} {problem.units} "
                f"({problem.body_names[second]} along the axis from "
                f"{problem.body_names[first]})"
            )
    return f"; at that assembly {', '.join(items)}" if items else ""


def _dimensions(problem: Problem, missing: np.ndarray, r: np.ndarray) -> str:
    """What cannot all hold, from the rows that miss: declared lengths as written, the
    bodies whose part drawings (anchors in their frames) miss, the sliding anchors off
    their joints' axis lines (and by how much), the joints whose axes miss."""
    rows = problem.rows
    n, count = len(rows.lengths), 3 * len(rows.local_joint)
    lines = 2 * len(rows.line_joint)
    texts = [problem.row_labels[k][2] for k in missing if k < n]
    parts = {
        problem.frame_names[rows.local_frame[(k - n) // 3]]
        for k in missing
        if n <= k < n + count
    }
    off = sorted({(k - n - count) // 2 for k in missing if 0 <= k - n - count < lines})
    axes = {problem.row_joints[k][0] for k in missing if k >= n + count + lines}
    if parts:
        names = ", ".join(b for b in problem.frame_names if b in parts)
        frames = "its frame" if len(parts) == 1 else "their frames"
        texts.append(f"the anchors of {names} in {frames}")
    for s in off:
        miss = np.linalg.norm(r[n + count + 2 * s : n + count + 2 * s + 2])
        joint = problem.joint_names[rows.line_joint[s]]
        body = problem.frame_names[rows.line_frame[s]]
        texts.append(
            f"{body}'s anchor of {joint} on the axis line of {joint} (off it by "
            f"{miss * problem.scale:.6g} {problem.units})"
        )
    if axes:
        names = ", ".join(problem.joint_names[j] for j in sorted(axes))
        texts.append(f"the axes of {names}")
    return "; ".join(dict.fromkeys(texts))


def _misses(r, missing, rows: Rows) -> tuple[float, float]:
    """The gap in reference lengths (|length - declared| per missing length row, the
    distance per local anchor, its 3 rows together, and per sliding anchor off its
    axis line, its 2 rows together) and the axes' miss in degrees (the angle per axis
    row)."""
    n, count = len(rows.lengths), 3 * len(rows.local_joint)
    lines = 2 * len(rows.line_joint)
    lengths = np.abs(r[:n]) * missing[:n]
    local = np.linalg.norm(r[n : n + count].reshape(-1, 3), axis=1)
    line = np.linalg.norm(r[n + count : n + count + lines].reshape(-1, 2), axis=1)
    start = n + count + lines
    axes = np.abs(r[start : start + len(rows.axis_p)])
    angle = np.degrees(np.arcsin(np.minimum(axes, 1.0)))
    return float(np.sum(lengths) + np.sum(local) + np.sum(line)), float(np.sum(angle))


def _loop(problem: Problem, missed: list[int]) -> tuple[list[int], list[int], int]:
    """The loop(s) of the body graph through the ``missed`` joints: joints and bodies
    in order around it (fundamental cycles from the ground, the one covering the most
    first; missed joints on none last), and how many loops."""
    cycles = _cycles(problem.pairs, problem.ground)
    chosen, left = [], set(missed)
    while left:
        best = max(
            cycles, key=lambda c: (len(left & set(c[0])), -len(c[0])), default=None
        )
        if best is None or not left & set(best[0]):
            break
        chosen.append(best)
        left -= set(best[0])
    joints = list(dict.fromkeys([j for c in chosen for j in c[0]] + sorted(left)))
    bodies = [b for c in chosen for b in c[1]] + [
        b for j in sorted(left) for b in problem.pairs[j]
    ]
    return joints, list(dict.fromkeys(bodies)), len(chosen)


def _cycles(pairs, ground: int) -> list[tuple[list[int], list[int]]]:
    """Fundamental cycles of the body graph (joints as edges) from a breadth-first tree
    at the ground: per joint off the tree, the joints and bodies around its cycle."""
    parent = {ground: (-1, -1)}  # body: (its parent body, the joint to it)
    order = [ground]
    for body in order:
        for j, pair in enumerate(pairs):
            other = pair[1] if pair[0] == body else pair[0] if pair[1] == body else -1
            if other >= 0 and other not in parent:
                parent[other] = (body, j)
                order.append(other)
    tree = {j for _, j in parent.values()}
    cycles = []
    for j, (u, v) in enumerate(pairs):
        if j in tree or u not in parent or v not in parent:
            continue
        up_u, up_v = _to_root(parent, u), _to_root(parent, v)
        top = next(b for b in up_u if b in up_v)
        down = up_u[: up_u.index(top) + 1][::-1]  # top ... u
        back = up_v[: up_v.index(top)]  # v ... (below top)
        joints = [parent[b][1] for b in down[1:]] + [j] + [parent[b][1] for b in back]
        cycles.append((joints, down + back))
    return cycles


def _to_root(parent, body: int) -> list[int]:
    path = [body]
    while parent[path[-1]][0] >= 0:
        path.append(parent[path[-1]][0])
    return path


def _held_axes(problem: Problem, joints: list[int]) -> str:
    """Which axes of the loop are held as written: on the ground, or on bodies given by
    world anchors (a body in its own frame carries its axes)."""
    held, on_ground, world = [], False, []
    for axis in problem.axes:
        if axis.joint in joints and axis.held_bodies:
            held.append(axis.joint)
            on_ground |= problem.ground in axis.held_bodies
            world += [b for b in axis.held_bodies if b != problem.ground]
    if not held:
        return ""
    names = ", ".join(
        problem.joint_names[j] for j in sorted(set(held), key=joints.index)
    )
    where = ["the ground"] if on_ground else []
    if world:
        bodies = ", ".join(problem.body_names[b] for b in dict.fromkeys(world))
        where.append(f"{bodies}, given by world anchors")
    hint = (
        "; give a body in its own frame for its axes to turn with it" if world else ""
    )
    return (
        f"; the axes of {names} are held as written (on {' and on '.join(where)}{hint})"
    )


def check_held_axes(rd: Reader, problem: Problem, anchors: np.ndarray) -> None:
    """A body given by world anchors holds its axes as written; refuse an assembly
    that turns it off them (its anchors' best-fit rotation, ``anchors (J, 3)`` file
    units, moves a held axis by more than :data:`HELD_AXIS_TOL`): the file it would
    write has axes that no longer belong to their bodies. A planar loop turns its
    bodies about their (common) axis and passes."""
    turned = list(_turned_off(problem, anchors))
    if not turned:
        return
    joints = sorted({j for _, held, _ in turned for j in held})
    loop, bodies, _ = _loop(problem, joints)
    names = [problem.body_names[b] for b, _, _ in turned]
    angles = ", ".join(
        f"{n} by {np.degrees(a):.3g}°" for n, (_, _, a) in zip(names, turned)
    )
    them = "it" if len(names) == 1 else "them"
    raise rd.fail(
        f"bodies[{turned[0][0]}]",
        f"the loop through joints {_names(problem.joint_names, loop)} (bodies "
        f"{_names(problem.body_names, bodies)}) closes only by turning {angles} off "
        f"the axes of {_names(problem.joint_names, joints)}, held as written on "
        f"bodies given by world anchors: give {', '.join(names)} in "
        f"{'its own frame' if len(names) == 1 else 'their own frames'} (frame, "
        f"anchors) for the axes to turn with {them}",
    )


def _turned_off(problem: Problem, anchors: np.ndarray):
    """Per body given by world anchors that holds axes: its held axes' joints and the
    largest angle its best-fit rotation turns them by, where above the tolerance."""
    for body in dict.fromkeys(
        b for axis in problem.axes for b in axis.held_bodies if b != problem.ground
    ):
        on = [j for j, pair in enumerate(problem.pairs) if body in pair]
        rot, _, _ = fit(problem.drawn[on], anchors[on])
        held = [
            (axis.joint, v)
            for axis in problem.axes
            for b, (_, v) in zip(axis.bodies, axis.carriers)
            if b == body
        ]
        angles = [np.arccos(np.clip((rot @ v) @ v, -1.0, 1.0)) for _, v in held]
        if max(angles) > HELD_AXIS_TOL:
            yield body, sorted({j for j, _ in held}), max(angles)


def _names(names, indices) -> str:
    return ", ".join(names[k] for k in indices)


def check_declared(rd: Reader, problem: Problem) -> None:
    """A file that is not assembled must already hold its declared lengths."""
    rows = problem.rows
    a = problem.anchors0
    got = np.linalg.norm(a[rows.pairs[:, 0]] - a[rows.pairs[:, 1]], axis=-1)
    for k in range(len(rows.lengths)):
        if abs(got[k] - rows.lengths[k]) > CHECK_TOL:
            where, _, text = problem.row_labels[k]
            raise rd.fail(
                where,
                f"the anchors are {got[k] * problem.scale:.12g} {problem.units} apart, "
                f"declared {text.split(' = ')[1]}: fix the anchors, or set "
                "[mechanism].assemble = true to assemble",
            )
