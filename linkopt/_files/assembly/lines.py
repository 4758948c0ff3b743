"""Prismatic and cylindrical joints in an assembly: the slide is free.

The joint's anchor belongs to its *holder*, the ground when the joint is on it and its
first body otherwise; the other body, the one that slides, only has to carry its anchor
of the joint onto the axis line through it (two rows, along two normals of the axis as
that body carries it), so the travel along the axis takes up what the drawing got
wrong (a rod drawn too long, a cylinder tilted off its pins). The axes stay parallel
and a prismatic joint does not turn about its axis (:func:`.axes.axis_rows`).

A body given by world anchors that carries such an axis is read as a part drawing at
its drawn pose (an *implicit* frame: identity orientation, its anchors and axes as
written): rigid, with its axis turning with it, as a body in its own frame. A declared
length between two of its anchors must then agree with the drawing.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..fields import field_name
from .axes import LINE_JOINTS, any_normal

#: A declared length between two anchors of a rigid body given by world anchors holds
#: to this (reference lengths), as the loader's check of a file that is not assembled.
RIGID_TOL = 1e-9


@dataclass(frozen=True)
class Slide:
    """A prismatic or cylindrical joint whose sliding body has a frame: its line rows
    are ``2 row, 2 row + 1``; ``sign`` +1 where the sliding body is the joint's second
    body (the slide is its anchor minus the joint's, along its axis), -1 where it is
    the first."""

    joint: int
    row: int
    sign: float
    body: int


def holder(pair, ground: int) -> int:
    """The body that holds a line joint's anchor: the ground, else the first body."""
    return ground if ground in pair else pair[0]


def slides_on(joint: dict, pair, body: int, ground: int) -> bool:
    """Whether ``body`` slides on ``joint`` (a line joint it does not hold)."""
    return joint.get("type") in LINE_JOINTS and body != holder(pair, ground)


def anchor_field(frame: dict, j: int, joints) -> str:
    """Where the anchor of joint ``j`` on ``frame``'s body is written."""
    if frame["implicit"]:
        return f"joints[{j}].anchor"
    return f"bodies[{frame['body']}].anchors.{field_name(joints[j]['name'])}"


def implicit_frames(bodies, joints, pairs, frames, anchors, ground) -> list[dict]:
    """The bodies given by world anchors that carry a prismatic or cylindrical axis,
    as frames at their drawn pose: origin ``origin`` or the centroid of their anchors,
    identity rotation, local anchors ``anchor - origin``, axes from ``[[joints]]``."""
    framed = {f["body"] for f in frames}
    out = []
    for k, body in enumerate(bodies):
        on = [j for j, pair in enumerate(pairs) if k in pair]
        if k == ground or k in framed:
            continue
        if not any(joints[j].get("type") in LINE_JOINTS for j in on):
            continue
        origin = (
            np.asarray(body["origin"], dtype=float)
            if _is_vector(body.get("origin"))
            else np.mean(anchors[on], axis=0)
        )
        out.append(
            {
                "body": k,
                "origin": origin,
                "name": body["name"],
                "rotation": np.eye(3),
                "anchors": {j: anchors[j] - origin for j in on},
                "axes": {},
                "implicit": True,
            }
        )
    return out


def _is_vector(value) -> bool:
    return (
        isinstance(value, list)
        and len(value) == 3
        and all(isinstance(v, (int, float)) and np.isfinite(v) for v in value)
    )


def check_rigid(rd, problem) -> None:
    """A declared length between two anchors of a body read as a part drawing at its
    drawn pose (:func:`implicit_frames`) must be the drawn distance: it is rigid.
    (Checked when assembling; a file that is not assembled has its lengths checked
    against its anchors anyway.)"""
    rows = problem.rows
    for f, implicit in enumerate(problem.frame_implicit):
        if not implicit:
            continue
        on = set(rows.local_joint[rows.local_frame == f]) | set(
            rows.line_joint[rows.line_frame == f]
        )
        for k, (i, j) in enumerate(rows.pairs):
            drawn = float(np.linalg.norm(problem.drawn[i] - problem.drawn[j]))
            if (
                i in on
                and j in on
                and abs(drawn - problem.declared[k]) > (RIGID_TOL * problem.scale)
            ):
                raise rd.fail(
                    f"lengths[{k}]",
                    f"{problem.joint_names[i]} and {problem.joint_names[j]} are both "
                    f"on body {problem.frame_names[f]!r}, which carries the axis of a "
                    "prismatic or cylindrical joint and so is rigid as drawn: its "
                    f"anchors are {drawn:.12g} {problem.units} apart, declared "
                    f"{problem.declared[k]:g}; fix the anchors, drop the length, or "
                    "give the body in its own frame",
                )


def line_rows(rd, frames, scale, joints, pairs, ground, axes):
    """Two rows per sliding body's anchor of its line joint: ``n_k · (a_j - p_b -
    R_b ℓ_bj) = 0`` for two normals ``n_k`` of the axis as the body carries it (turned
    with its frame); the arrays, the row labels and the :class:`Slide` of each."""
    frame, joint, at, normals, labels, slides = [], [], [], [], [], []
    for f_index, f in enumerate(frames):
        for j, local in f["anchors"].items():
            if not slides_on(joints[j], pairs[j], f["body"], ground):
                continue
            v = _carried(axes, j, f["body"])
            if v is None:
                raise rd.fail(
                    f"joints[{j}].axis",
                    f"missing required field for a {joints[j]['type']} joint",
                )
            u = any_normal(v)
            slides.append(
                Slide(
                    j, len(frame), 1.0 if f["body"] == pairs[j][1] else -1.0, f["body"]
                )
            )
            frame.append(f_index)
            joint.append(j)
            at.append(local / scale)
            normals.append([u, np.cross(v, u)])
            name = joints[j]["name"]
            text = f"{f['name']}'s anchor of {name} on its axis line"
            labels += [(anchor_field(f, j, joints), (), text, (j,))] * 2
    arrays = {
        "line_frame": np.array(frame, dtype=int),
        "line_joint": np.array(joint, dtype=int),
        "line_at": np.array(at, dtype=float).reshape(-1, 3),
        "line_n": np.array(normals, dtype=float).reshape(-1, 2, 3),
    }
    return arrays, labels, tuple(slides)


def _carried(axes, j: int, body: int):
    """The drawn world direction of joint ``j``'s axis as ``body`` carries it."""
    for axis in axes:
        if axis.joint == j and axis.key == "axis" and body in axis.bodies:
            return axis.carriers[axis.bodies.index(body)][1]
    return None
