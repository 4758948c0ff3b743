"""The axes bodies carry and the held motors: their rows of an assembly problem.

A body given in its own frame carries each of its joint axes (from its ``axes``, in its
frame, or from ``[[joints]]``, the world direction at its drawn pose) and turns it; the
ground and a body given by world anchors hold theirs as written. Each joint keeps its
carriers' axes parallel (two rows) or, for a universal joint, perpendicular (one row).
A motor holds its drawn value about its axis as its first body carries it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..._engine.model import MOTOR_JOINTS
from ..fields import shown

#: Joint kinds whose one axis both bodies carry (their axes stay parallel).
SHARED_AXIS = ("revolute", "prismatic", "cylindrical")
#: Joint kinds whose bodies slide along the axis: the second body's anchor of the
#: joint only has to lie on the axis line through the first's (the slide is free).
LINE_JOINTS = ("prismatic", "cylindrical")
#: The motor fields of :class:`~linkopt._files.assembly.problem.Rows`.
MOTOR_FIELDS = (
    "motor_linear",
    "motor_frame",
    "motor_joint",
    "motor_moved",
    "motor_base",
    "motor_axis",
    "motor_e",
    "motor_f",
    "motor_target",
)


@dataclass(frozen=True)
class Axis:
    """One axis of joint ``joint`` (field ``key``) and the bodies that carry it: per
    carrier, its frame index (-1: held as written, on the ground or a body given by
    world anchors) and its world direction as drawn."""

    joint: int
    key: str
    carriers: tuple[tuple[int, np.ndarray], ...]
    bodies: tuple[int, ...]  # the carrying bodies

    @property
    def held_bodies(self) -> tuple[int, ...]:
        """The carriers that hold the axis as written."""
        return tuple(b for b, (f, _) in zip(self.bodies, self.carriers) if f < 0)


def axis_key(joint: dict, pair, body: int) -> str | None:
    """The axis field of ``joint`` that ``body`` carries, if any."""
    kind = joint.get("type")
    if kind in SHARED_AXIS:
        return "axis"
    if kind == "universal":
        return "axis" if pair[0] == body else "axis2"
    return None


def read_axes(rd, frames, joints, pairs) -> tuple[Axis, ...]:
    """The axes the bodies carry: per joint axis, each carrier's frame (or -1 where
    it is held: on the ground, or on a body given by world anchors) and its world
    direction as drawn (from the body's ``axes``, else the joint's field)."""
    frame_of = {f["body"]: k for k, f in enumerate(frames)}
    axes = []
    for j, joint in enumerate(joints):
        for key, sides in _axis_sides(joint):
            carriers = [_carrier(frames, frame_of, j, pairs[j][s]) for s in sides]
            if all(v is not None for _, v in carriers) and key in joint:
                raise rd.fail(
                    f"joints[{j}].{key}",
                    f"the {key} of joint {joint['name']!r} is given in the axes of "
                    "the body frames that carry it; give it once: drop one of them",
                )
            if key not in joint and all(v is None for _, v in carriers):
                continue  # none given: the loader says so
            if key not in joint and any(v is None for _, v in carriers):
                raise rd.fail(
                    f"joints[{j}].{key}",
                    f"missing: a body that carries the {key} of {joint['name']!r} "
                    "without a frame (or without it in its axes) needs it here",
                )
            world = rd.direction(joint, key, f"joints[{j}]") if key in joint else None
            carried = tuple((f, world if v is None else v) for f, v in carriers)
            axes.append(Axis(j, key, carried, tuple(pairs[j][s] for s in sides)))
    return tuple(axes)


def _axis_sides(joint: dict) -> tuple[tuple[str, tuple[int, ...]], ...]:
    """Each axis field of a joint and the sides (0: first body) that carry it."""
    kind = joint.get("type")
    if kind in SHARED_AXIS:
        return (("axis", (0, 1)),)
    if kind == "universal":
        return (("axis", (0,)), ("axis2", (1,)))
    return ()


def _carrier(frames, frame_of, j, body) -> tuple[int, np.ndarray | None]:
    """A body's frame index (-1 if it has none) and its drawn world direction of
    joint ``j``'s axis when it gives it in its ``axes``."""
    f = frame_of.get(body, -1)
    if f < 0 or j not in frames[f]["axes"]:
        return f, None
    return f, frames[f]["rotation"] @ frames[f]["axes"][j]


def axis_rows(axes: tuple[Axis, ...], joints):
    """Rows ``p · q = 0`` that keep the carriers of each axis together: two for a
    shared axis (``q`` ⟂ two normals ``p`` of the first carrier: parallel), a third for
    a prismatic joint (no turn about the axis: the normal ``u`` of the first carrier
    and the normal of the second nearest to it, ``u₂``, keep ``(n × u) · u₂ = 0``, as
    drawn), one for a universal joint (its two axes perpendicular). None where no
    carrier moves."""
    p_frame, p_vec, q_frame, q_vec, labels = [], [], [], [], []
    for axis in axes:
        name = joints[axis.joint]["name"]
        if len(axis.carriers) == 1:  # a universal joint: axis ⟂ axis2
            partner = _partner(axes, axis)
            if axis.key == "axis2" or partner is None:
                continue  # axis2 is its partner's row; a missing one the loader says
            (fp, vp), (fq, vq) = axis.carriers[0], partner.carriers[0]
            pairs = [(vp, vq)]
            text = f"the axes of {name} (perpendicular)"
        else:  # a held carrier first, so that its normals are fixed
            (fp, vp), (fq, vq) = sorted(axis.carriers, key=lambda c: c[0] >= 0)
            u = any_normal(vp)
            pairs = [(u, vq), (np.cross(vp, u), vq)]
            text = f"the {axis.key} of {name}"
            if joints[axis.joint].get("type") == "prismatic":
                pairs.append((np.cross(vp, u), _nearest_normal(u, vq)))
        if fp < 0 and fq < 0:
            continue  # held on both sides: nothing moves it
        for p, q in pairs:
            p_frame.append(fp)
            p_vec.append(p)
            q_frame.append(fq)
            q_vec.append(q)
            labels.append((f"joints[{axis.joint}].{axis.key}", (), text, (axis.joint,)))
    arrays = {
        "axis_p": np.array(p_frame, dtype=int),
        "axis_vp": np.array(p_vec, dtype=float).reshape(-1, 3),
        "axis_q": np.array(q_frame, dtype=int),
        "axis_vq": np.array(q_vec, dtype=float).reshape(-1, 3),
    }
    return arrays, labels


def _nearest_normal(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """The unit normal of ``v`` nearest ``u`` (``u`` with its part along ``v``
    removed); any normal where ``u`` is along ``v``."""
    w = u - (u @ v) * v
    norm = np.linalg.norm(w)
    return w / norm if norm > 1e-9 else any_normal(v)


def _partner(axes: tuple[Axis, ...], axis: Axis) -> Axis | None:
    """A universal joint's ``axis2`` given its ``axis`` (None if not given)."""
    return next((a for a in axes if a.joint == axis.joint and a.key == "axis2"), None)


def read_motors(
    rd, data, joints, joint_index, pairs, anchors, ground, scale, turns, axes
):
    """One row per motor that moves an anchor: its drawn value (+ ``turns``), about
    its axis as its first body carries it."""
    items = rd.entries(data, "motors", required=False)
    if turns is None:
        turns = np.zeros(len(items))
    turns = np.asarray(turns, dtype=float)
    if turns.shape != (len(items),):
        raise rd.fail(
            "[[motors]]", f"expected {len(items)} motor values, got {turns.size}"
        )
    fields = {key: [] for key in MOTOR_FIELDS}
    names, labels = [], []
    for k, item in enumerate(items):
        where = f"motors[{k}]"
        if "joint" not in item or "name" not in item:
            raise rd.fail(where, "a motor needs name and joint")
        m = rd.lookup(joint_index, item["joint"], f"{where}.joint", "joint")
        kind = joints[m].get("type")
        if kind not in MOTOR_JOINTS:
            raise rd.fail(
                f"{where}.joint",
                f"joint {item['joint']!r} is {shown(kind)}; a motor drives a "
                f"{' or '.join(MOTOR_JOINTS)} joint",
            )
        carried = next((a for a in axes if a.joint == m and a.key == "axis"), None)
        if carried is None:
            raise rd.fail(
                f"joints[{m}].axis", f"missing required field for a {kind} joint"
            )
        frame, axis = carried.carriers[0]  # as its first body carries it
        row = _motor_row(m, pairs, anchors / scale, ground, axis, MOTOR_JOINTS[kind])
        if row is None:
            continue
        row["motor_frame"] = frame
        value = turns[k] / (scale if MOTOR_JOINTS[kind] else 1.0)
        row["motor_target"] = row["motor_target"] + value
        for key in fields:
            fields[key].append(row[key])
        names.append(str(item["name"]))
        labels.append((where, (joints[m]["name"],), f"motor {item['name']}", (m,)))
    arrays = {
        "motor_linear": np.array(fields["motor_linear"], dtype=bool),
        "motor_frame": np.array(fields["motor_frame"], dtype=int),
        "motor_joint": np.array(fields["motor_joint"], dtype=int),
        "motor_moved": np.array(fields["motor_moved"], dtype=int),
        "motor_base": np.array(fields["motor_base"], dtype=int),
        "motor_axis": np.array(fields["motor_axis"], dtype=float).reshape(-1, 3),
        "motor_e": np.array(fields["motor_e"], dtype=float).reshape(-1, 3),
        "motor_f": np.array(fields["motor_f"], dtype=float).reshape(-1, 3),
        "motor_target": np.array(fields["motor_target"], dtype=float),
    }
    return arrays, tuple(names), labels


def _farthest(body, m, pairs, anchors, axis, linear) -> int:
    """The anchor of ``body`` (other than joint ``m``) farthest from the motor's axis
    line (rotary: -1 when none is off it) or point (linear: any other anchor, a slider
    pinned at its rail anchor too; -1 when it has none)."""
    best, best_d = -1, -1.0 if linear else 1e-9
    for j, pair in enumerate(pairs):
        if j == m or body not in pair:
            continue
        v = anchors[j] - anchors[m]
        d = np.linalg.norm(v if linear else v - (v @ axis) * axis)
        if d > best_d:
            best, best_d = j, d
    return best


def _motor_row(m, pairs, anchors, ground, axis, linear) -> dict | None:
    """The held-motor row of joint ``m``: the second body's farthest anchor, measured
    against the first body's (or the world, for the ground)."""
    first, second = pairs[m]
    moved = _farthest(second, m, pairs, anchors, axis, linear)
    if moved < 0:
        return None  # nothing on the second body for the motor to place
    base = -1 if first == ground else _farthest(first, m, pairs, anchors, axis, linear)
    v = anchors[moved] - anchors[m]
    e = v - (v @ axis) * axis
    e = e / np.linalg.norm(e) if np.linalg.norm(e) > 1e-9 else any_normal(axis)
    f = np.cross(axis, e)
    if linear:
        ref = anchors[m] if base < 0 else anchors[base]
        target = (anchors[moved] - ref) @ axis
    elif base < 0:
        target = 0.0
    else:
        w = anchors[base] - anchors[m]
        target = -np.arctan2(w @ f, w @ e)
    return {
        "motor_linear": linear,
        "motor_joint": m,
        "motor_moved": moved,
        "motor_base": base,
        "motor_axis": axis,
        "motor_e": e,
        "motor_f": f,
        "motor_target": float(target),
    }


def any_normal(axis: np.ndarray) -> np.ndarray:
    helper = np.eye(3)[int(np.argmin(np.abs(axis)))]
    e = helper - (helper @ axis) * axis
    return e / np.linalg.norm(e)
