"""Writing an assembly: the assembled definition (world anchors and axes, frames
resolved, points carried) and the report of what moved."""

from __future__ import annotations

import copy
from dataclasses import dataclass

import numpy as np

from ..._engine.rotations import matrix_exp, turn_onto
from ..fields import is_number_list
from .axes import any_normal
from .problem import BODY_KEYS, Problem
from .solve import residual_np, start


@dataclass(frozen=True)
class Move:
    """How far one joint anchor moved (file units)."""

    joint: str
    before: tuple[float, float, float]
    after: tuple[float, float, float]
    distance: float


@dataclass(frozen=True)
class Report:
    """What an assembly did: the moves, the declared lengths as achieved, the slides
    (per prismatic or cylindrical joint whose sliding body has a frame: where that
    body's anchor of the joint sat along the axis from the joint's, drawn and
    assembled, file units), the largest constraint residual left (file units for
    lengths) and the iteration counts."""

    moves: tuple[Move, ...]
    lengths: tuple[tuple[tuple[str, str], float, float], ...]  # (pair, declared, got)
    slides: tuple[tuple[str, float, float], ...]  # (joint, drawn, assembled)
    residual: float
    iterations: int
    units: str

    @property
    def largest_move(self) -> float:
        return max((m.distance for m in self.moves), default=0.0)


def strip(data: dict) -> dict:
    """The definition without what only assembly reads."""
    out = copy.deepcopy(data)
    out.pop("lengths", None)
    if isinstance(out.get("mechanism"), dict):
        out["mechanism"].pop("assemble", None)
    return out


def written(data: dict, problem: Problem, x: np.ndarray) -> dict:
    """The assembled definition: world anchors at full precision, frames resolved."""
    out = strip(data)
    count = len(problem.joint_names)
    anchors = assembled_anchors(problem, x)
    poses = x[3 * count :].reshape(-1, 6)
    for k, joint in enumerate(out["joints"]):
        _set_anchor(joint, anchors[k])
    rotations = _frame_rotations(problem, poses)
    _set_axes(out, problem, rotations)
    for f, b in enumerate(problem.frame_bodies):
        body = out["bodies"][b]
        if problem.frame_implicit[f]:  # given by world anchors: its origin, if any
            if "origin" in body:
                body["origin"] = [float(v) for v in poses[f, :3] * problem.scale]
            continue
        for key in BODY_KEYS:
            body.pop(key, None)
        body["origin"] = [float(v) for v in poses[f, :3] * problem.scale]
    _carry_points(out, problem, anchors, poses, rotations)
    return out


def assembled_anchors(problem: Problem, x: np.ndarray) -> np.ndarray:
    """World anchors in file units; held ones exactly as drawn."""
    count = len(problem.joint_names)
    anchors = x[: 3 * count].reshape(count, 3) * problem.scale
    return np.where(problem.held[:, None], problem.drawn, anchors)


def _set_anchor(joint: dict, anchor: np.ndarray) -> None:
    """``anchor`` after ``bodies`` (where the loader's files keep it)."""
    _set_after(joint, "anchor", [float(v) for v in anchor], "bodies")


def _set_after(joint: dict, key: str, value, after: str) -> None:
    """``joint[key] = value``, a new key placed right after ``after``."""
    if key in joint:
        joint[key] = value
        return
    items = list(joint.items())
    joint.clear()
    for k, v in items:
        joint[k] = v
        if k == after:
            joint[key] = value
    joint.setdefault(key, value)


def _set_axes(out: dict, problem: Problem, rotations: np.ndarray) -> None:
    """World axes at the assembled pose. An axis held by one of its carriers stays as
    written; one that only bodies in their own frames carry turns with the first."""
    for axis in problem.axes:
        joint = out["joints"][axis.joint]
        if axis.held_bodies:
            continue
        f, drawn = axis.carriers[0]
        local = problem.rows.rotation0[f].T @ drawn
        turned = rotations[f] @ local
        after = "axis" if axis.key == "axis2" and "axis" in joint else "anchor"
        _set_after(
            joint, axis.key, [float(v) for v in turned / np.linalg.norm(turned)], after
        )


def _frame_rotations(problem: Problem, poses: np.ndarray) -> np.ndarray:
    import jax.numpy as jnp

    if not len(poses):
        return np.zeros((0, 3, 3))
    turn = np.asarray(matrix_exp(jnp.asarray(poses[:, 3:])))
    return np.einsum("fij,fjk->fik", turn, problem.rows.rotation0)


def _carry_points(out, problem, anchors, poses, rotations) -> None:
    """Points given by ``position`` move with their body: on a body given in its own
    frame the position is in that frame (as its anchors are); on any other body it is
    a world position at rest, carried by the body's frame when it has one read from
    its drawing (:func:`.lines.implicit_frames`), else by the best-fit rigid motion of
    its anchors."""
    names = [b.get("name") for b in out["bodies"]]
    frame_of = {b: f for f, b in enumerate(problem.frame_bodies)}
    scale = problem.scale
    for point in out.get("points", []):
        if not isinstance(point, dict) or "position" not in point:
            continue
        if not is_number_list(point["position"], 3) or point.get("body") not in names:
            continue  # the loader reports it
        b = names.index(point["body"])
        old = np.asarray(point["position"], dtype=float)
        if b in frame_of:  # in the body frame, or at its drawn pose (implicit)
            f = frame_of[b]
            local = (
                old - problem.frames0[f] * scale if problem.frame_implicit[f] else old
            )
            new = poses[f, :3] * scale + rotations[f] @ local
        else:
            on = [j for j in range(len(anchors)) if b in _bodies_of(out, j, names)]
            rot, before, after = fit(problem.anchors0[on] * scale, anchors[on])
            new = after + rot @ (old - before)
        point["position"] = [float(v) for v in new]


def _bodies_of(out, j, names) -> tuple[int, ...]:
    return tuple(names.index(b) for b in out["joints"][j]["bodies"])


def fit(before: np.ndarray, after: np.ndarray):
    """Rigid motion taking ``before (n, 3)`` nearest to ``after``: rotation and the two
    centroids (Kabsch; the smallest aligning rotation for collinear anchors)."""
    c0, c1 = before.mean(axis=0), after.mean(axis=0)
    p, q = before - c0, after - c1
    sv = np.linalg.svd(p, compute_uv=False) if len(p) > 1 else np.zeros(1)
    if len(p) >= 3 and sv[1] > 1e-9 * max(sv[0], 1e-300):
        u, _, vt = np.linalg.svd(p.T @ q)
        d = np.sign(np.linalg.det(vt.T @ u.T))
        return vt.T @ np.diag([1.0, 1.0, d]) @ u.T, c0, c1
    if len(p) < 2 or sv[0] < 1e-12:
        return np.eye(3), c0, c1
    u = np.linalg.svd(p)[2][0]
    v = np.linalg.svd(q)[2][0]
    v = v if (p @ u) @ (q @ v) >= 0 else -v
    return _aligning(u, v), c0, c1


def _aligning(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """The smallest rotation taking unit ``u`` to unit ``v`` (a half turn about a
    normal of ``u`` for ``v = -u``)."""
    if float(u @ v) < -1 + 1e-12:
        n = any_normal(u)
        return 2.0 * np.outer(n, n) - np.eye(3)
    return turn_onto(np, u, v, np.eye(3)).T  # its columns: the turned unit vectors


def report(problem: Problem, x: np.ndarray, residual: float, iterations: int) -> Report:
    after, before = assembled_anchors(problem, x), problem.drawn
    moves = tuple(
        Move(
            name,
            tuple(float(v) for v in b),
            tuple(float(v) for v in a),
            float(np.linalg.norm(a - b)),
        )
        for name, b, a in zip(problem.joint_names, before, after)
    )
    rows = problem.rows
    lengths = tuple(
        (
            (problem.joint_names[i], problem.joint_names[j]),
            problem.declared[k],
            float(np.linalg.norm(after[i] - after[j])),
        )
        for k, (i, j) in enumerate(rows.pairs)
    )
    drawn = {j: v for j, _, v in slide_values(problem, start(problem))}
    slides = tuple(
        (problem.joint_names[j], drawn[j], v) for j, _, v in slide_values(problem, x)
    )
    return Report(
        moves,
        lengths,
        slides,
        _geometric_residual(problem, x),
        iterations,
        problem.units,
    )


def slide_values(problem: Problem, x: np.ndarray):
    """Per :class:`~.lines.Slide`: (joint, sliding body, slide in file units), where
    the slide is the second body's anchor of the joint minus the first's along the
    axis as the sliding body carries it (turned with its frame)."""
    import jax.numpy as jnp

    count = len(problem.joint_names)
    anchors = x[: 3 * count].reshape(count, 3)
    poses = x[3 * count :].reshape(-1, 6)
    rows = problem.rows
    turn = np.asarray(matrix_exp(jnp.asarray(poses[:, 3:]))) if len(poses) else poses
    out = []
    for slide in problem.slides:
        f, j = rows.line_frame[slide.row], rows.line_joint[slide.row]
        at = poses[f, :3] + turn[f] @ rows.rotation0[f] @ rows.line_at[slide.row]
        n = turn[f] @ np.cross(*rows.line_n[slide.row])
        value = slide.sign * float((at - anchors[j]) @ n) * problem.scale
        out.append((j, slide.body, value))
    return out


def _geometric_residual(problem: Problem, x: np.ndarray) -> float:
    """Largest miss of a declared length, local anchor or sliding anchor off its axis
    line (file units)."""
    sizes = (len(problem.joint_names), len(problem.frame_names))
    rows = problem.rows
    count = len(rows.lengths) + 3 * len(rows.local_joint) + 2 * len(rows.line_joint)
    r = residual_np(sizes, problem.rows, x)[:count]
    return float(np.max(np.abs(r), initial=0.0)) * problem.scale
