"""An assembly problem read from a parsed definition: the unknowns' drawn values and the
constraint rows (declared lengths, local anchors of bodies in their own frames, axes,
held motors), homogenised by the reference length; every field it uses checked."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from jaxtyping import Float

from ..fields import Reader, is_number_list, shown
from .axes import (
    LINE_JOINTS,
    Axis,
    axis_key,
    axis_rows,
    read_axes,
    read_motors,
)
from .lines import (
    Slide,
    anchor_field,
    holder,
    implicit_frames,
    line_rows,
    slides_on,
)

BODY_KEYS = ("frame", "orientation", "anchors", "axes")


@dataclass(frozen=True)
class Rows:
    """The constraint rows of an assembly (homogenised), as arrays; registered as a
    pytree (all data fields) when the solver's programs are built, since this module
    is read without JAX.

    ``J`` joints, ``F`` bodies in their own frame, ``N`` lengths, ``R`` local anchors,
    ``S`` anchors on a slide line, ``A`` axis rows, ``M`` held motors. A vector carried
    by frame ``f`` turns with the frame's turn from the drawing; a held one (``-1``)
    stays as written.
    """

    pairs: np.ndarray  # (N, 2) int joint indices
    lengths: np.ndarray  # (N,)
    local_frame: np.ndarray  # (R,) int frame index
    local_joint: np.ndarray  # (R,) int joint index
    local_at: np.ndarray  # (R, 3) anchor in the body frame
    line_frame: np.ndarray  # (S,) int frame index of the sliding body
    line_joint: np.ndarray  # (S,) int its prismatic or cylindrical joint
    line_at: np.ndarray  # (S, 3) its anchor of the joint in its frame
    line_n: np.ndarray  # (S, 2, 3) two normals of its axis (world, as drawn)
    rotation0: np.ndarray  # (F, 3, 3) drawn frame orientations
    axis_p: np.ndarray  # (A,) int frame carrying p, -1 for a held (world) vector
    axis_vp: np.ndarray  # (A, 3) p as drawn (world, at the drawn frame)
    axis_q: np.ndarray  # (A,) int frame carrying q, -1 for a held vector
    axis_vq: np.ndarray  # (A, 3) q as drawn: each row is p · q = 0
    motor_linear: np.ndarray  # (M,) bool
    motor_frame: np.ndarray  # (M,) int: the frame of the first body, -1 if held
    motor_joint: np.ndarray  # (M,) int: the motor's joint (its axis point)
    motor_moved: np.ndarray  # (M,) int: an anchor of the second body
    motor_base: np.ndarray  # (M,) int: an anchor of the first body, -1 for ground
    motor_axis: np.ndarray  # (M, 3) unit axis n
    motor_e: np.ndarray  # (M, 3) unit, ⟂ n: angle zero
    motor_f: np.ndarray  # (M, 3) n × e
    motor_target: np.ndarray  # (M,) rad or reference lengths


@dataclass(frozen=True)
class Problem:
    """An assembly problem read from a file (homogenised by ``scale``)."""

    joint_names: tuple[str, ...]
    drawn: np.ndarray  # (J, 3) drawn anchors, file units
    anchors0: np.ndarray  # (J, 3) drawn anchors, homogenised
    held: np.ndarray  # (J,) bool: on the ground
    frame_names: tuple[str, ...]  # bodies in their own frame
    frame_bodies: tuple[int, ...]
    frames0: np.ndarray  # (F, 3) drawn frame origins
    frame_implicit: tuple[bool, ...]  # a body given by world anchors, read as a frame
    rows: Rows
    row_labels: tuple[tuple[str, tuple[str, ...], str], ...]  # (where, joints, text)
    row_joints: tuple[tuple[int, ...], ...]  # per row, the joints it concerns
    axes: tuple[Axis, ...]  # the joint axes bodies carry
    slides: tuple[Slide, ...]
    pairs: tuple[tuple[int, int], ...]  # per joint, its two bodies
    body_names: tuple[str, ...]
    ground: int
    declared: tuple[float, ...]  # the lengths as written (file units)
    motor_names: tuple[str, ...]
    scale: float
    units: str


def frame_bodies(data: dict) -> list[int]:
    """The indices of the bodies given in their own frame (any of :data:`BODY_KEYS`)."""
    bodies = data.get("bodies")
    if not isinstance(bodies, list):
        return []
    return [
        k
        for k, b in enumerate(bodies)
        if isinstance(b, dict) and any(key in b for key in BODY_KEYS)
    ]


def read_problem(data: dict, source: str, motors=None) -> Problem:
    """The assembly problem of a parsed definition, every field it uses checked."""
    rd = Reader(source)
    head = _head(rd, data)
    bodies = rd.entries(data, "bodies", required=True)
    body_index = rd.names(bodies, "bodies")
    ground = rd.lookup(body_index, head["ground"], "[mechanism].ground", "body")
    joints = rd.entries(data, "joints", required=True)
    joint_index = rd.names(joints, "joints")
    pairs = [
        _joint_pair(rd, j, f"joints[{k}]", body_index) for k, j in enumerate(joints)
    ]
    frames = _read_frames(rd, bodies, ground, joint_index, pairs, joints)
    anchors0 = _drawn_anchors(rd, joints, pairs, frames, ground)
    frames += implicit_frames(bodies, joints, pairs, frames, anchors0, ground)
    scale = _scale(rd, head, anchors0)
    lengths, length_labels = _read_lengths(rd, data, joint_index, scale)
    axes = read_axes(rd, frames, joints, pairs)
    local, local_labels = _local_rows(frames, scale, joints, pairs, ground)
    line, line_labels, slides = line_rows(
        rd, frames, scale, joints, pairs, ground, axes
    )
    axis_arrays, axis_labels = axis_rows(axes, joints)
    motor_rows, motor_names, motor_labels = read_motors(
        rd, data, joints, joint_index, pairs, anchors0, ground, scale, motors, axes
    )
    rows = Rows(
        pairs=lengths[0],
        lengths=lengths[1],
        local_frame=local[0],
        local_joint=local[1],
        local_at=local[2],
        **line,
        rotation0=np.array([f["rotation"] for f in frames]).reshape(-1, 3, 3),
        **axis_arrays,
        **motor_rows,
    )
    labels = length_labels + local_labels + line_labels + axis_labels + motor_labels
    return Problem(
        joint_names=tuple(j["name"] for j in joints),
        drawn=anchors0,
        anchors0=anchors0 / scale,
        held=np.array([ground in p for p in pairs], dtype=bool),
        frame_names=tuple(bodies[f["body"]]["name"] for f in frames),
        frame_bodies=tuple(f["body"] for f in frames),
        frames0=np.array([f["origin"] for f in frames]).reshape(-1, 3) / scale,
        frame_implicit=tuple(f["implicit"] for f in frames),
        rows=rows,
        row_labels=tuple(lab[:3] for lab in labels),
        row_joints=tuple(lab[3] for lab in labels),
        axes=axes,
        slides=slides,
        pairs=tuple(pairs),
        body_names=tuple(b["name"] for b in bodies),
        ground=ground,
        declared=tuple(float(v["length"]) for v in data.get("lengths", [])),
        motor_names=motor_names,
        scale=scale,
        units=str(head.get("units", "file units")),
    )


def _head(rd: Reader, data: dict) -> dict:
    """``[mechanism]``, with its ``ground``."""
    if "mechanism" not in data:
        raise rd.fail("[mechanism]", "missing table")
    head = data["mechanism"]
    if not isinstance(head, dict):
        raise rd.fail("[mechanism]", f"expected a table, got {shown(head)}")
    if "ground" not in head:
        raise rd.fail("[mechanism].ground", "missing required field")
    return head


def _joint_pair(rd: Reader, joint: dict, where: str, body_index) -> tuple[int, int]:
    if "bodies" not in joint:
        raise rd.fail(f"{where}.bodies", "missing required field")
    pair = joint["bodies"]
    if not isinstance(pair, list) or len(pair) != 2:
        raise rd.fail(
            f"{where}.bodies", f"expected a list of two body names, got {shown(pair)}"
        )
    return tuple(rd.lookup(body_index, b, f"{where}.bodies", "body") for b in pair)


def _read_frames(rd, bodies, ground, joint_index, pairs, joints) -> list[dict]:
    """Bodies given in their own frame: origin, rotation, local anchors and axes."""
    frames = []
    for k in frame_bodies({"bodies": bodies}):
        where, body = f"bodies[{k}]", bodies[k]
        if k == ground:
            raise rd.fail(
                where, "the ground is the world frame; give its anchors in [[joints]]"
            )
        for key in ("frame", "anchors"):
            if key not in body:
                raise rd.fail(
                    f"{where}.{key}",
                    "missing; a body in its own frame needs frame and anchors",
                )
        if "origin" in body:
            raise rd.fail(
                f"{where}.origin",
                "a body in its own frame has its origin at frame; give one of them",
            )
        frames.append(
            {
                "body": k,
                "origin": rd.vector(body, "frame", where),
                "name": body["name"],
                "rotation": _orientation(rd, body, where),
                "anchors": _local_anchors(rd, body, where, k, joint_index, pairs),
                "axes": _local_axes(rd, body, where, k, joint_index, pairs, joints),
                "implicit": False,
            }
        )
    return frames


def _orientation(rd: Reader, body: dict, where: str) -> Float[np.ndarray, "3 3"]:
    """``orientation``: a quaternion ``[w, x, y, z]`` (normalised), body to world."""
    if "orientation" not in body:
        return np.eye(3)
    q = body["orientation"]
    if not is_number_list(q, 4) or np.linalg.norm(q) < 1e-12:
        raise rd.fail(
            f"{where}.orientation",
            f"expected a quaternion [w, x, y, z] of 4 finite numbers, not all zero, "
            f"got {shown(q)}",
        )
    w, x, y, z = np.asarray(q, dtype=float) / np.linalg.norm(q)
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )


def _local_anchors(rd, body, where, k, joint_index, pairs) -> dict[int, np.ndarray]:
    """``anchors``: every joint of the body, by name, in the body frame."""
    table = body["anchors"]
    if not isinstance(table, dict):
        raise rd.fail(
            f"{where}.anchors",
            f"expected a table of joint name = [x, y, z], got {shown(table)}",
        )
    local = {}
    for name in table:
        joint = rd.lookup(joint_index, name, f"{where}.anchors", "joint")
        if k not in pairs[joint]:
            raise rd.fail(
                f"{where}.anchors",
                f"joint {name!r} does not touch body {body['name']!r}",
            )
        local[joint] = rd.vector(table, name, f"{where}.anchors")
    names = {v: n for n, v in joint_index.items()}
    for joint, pair in enumerate(pairs):
        if k in pair and joint not in local:
            raise rd.fail(
                f"{where}.anchors",
                f"missing joint {names[joint]!r}: a body in its own frame lists the "
                "anchors of all its joints",
            )
    return local


def _local_axes(
    rd, body, where, k, joint_index, pairs, joints
) -> dict[int, np.ndarray]:
    """``axes`` (optional): joint axes in the body frame, by joint name (normalised);
    the axis this body carries (a universal joint's ``axis`` on its first body,
    ``axis2`` on its second)."""
    table = body.get("axes", {})
    if not isinstance(table, dict):
        raise rd.fail(
            f"{where}.axes",
            f"expected a table of joint name = [x, y, z], got {shown(table)}",
        )
    local = {}
    for name in table:
        joint = rd.lookup(joint_index, name, f"{where}.axes", "joint")
        if k not in pairs[joint]:
            raise rd.fail(
                f"{where}.axes", f"joint {name!r} does not touch body {body['name']!r}"
            )
        if axis_key(joints[joint], pairs[joint], k) is None:
            raise rd.fail(
                f"{where}.axes",
                f"joint {name!r} is {shown(joints[joint].get('type'))}: it has no "
                "axis for a body to carry",
            )
        local[joint] = rd.direction(table, name, f"{where}.axes")
    return local


def _drawn_anchors(rd, joints, pairs, frames, ground) -> Float[np.ndarray, "J 3"]:
    """Each joint's drawn world anchor: ``anchor``, or where the frames of its bodies
    put it (their mean; a prismatic or cylindrical joint's is its first body's, along
    whose axis line the second slides). A joint whose both bodies give it in their
    frames has no ``anchor`` (it would be given twice); every other joint needs one."""
    images: dict[int, dict[int, np.ndarray]] = {}
    for f in frames:
        for joint, at in f["anchors"].items():
            images.setdefault(joint, {})[f["body"]] = f["origin"] + f["rotation"] @ at
    anchors = np.zeros((len(joints), 3))
    for k, joint in enumerate(joints):
        where, given = f"joints[{k}]", "anchor" in joint
        if given and len(images.get(k, {})) == 2:
            raise rd.fail(
                f"{where}.anchor",
                f"joint {joint['name']!r} is placed by the frames of both its bodies; "
                "give it once: drop anchor, or drop it from one body's anchors",
            )
        if given:
            anchors[k] = rd.vector(joint, "anchor", where)
        elif ground in pairs[k]:
            raise rd.fail(
                f"{where}.anchor",
                "missing required field: a joint on the ground is placed in the world",
            )
        elif joint.get("type") in LINE_JOINTS and holder(
            pairs[k], ground
        ) in images.get(k, {}):
            anchors[k] = images[k][holder(pairs[k], ground)]
        elif k in images:
            anchors[k] = np.mean(list(images[k].values()), axis=0)
        else:
            raise rd.fail(f"{where}.anchor", "missing required field")
    return anchors


def _scale(rd: Reader, head: dict, anchors: np.ndarray) -> float:
    """The reference length: given, or the span of the drawn anchors."""
    if "reference_length" in head:
        return rd.positive(head, "reference_length", "[mechanism]")
    span = float(np.max(np.linalg.norm(anchors[:, None] - anchors[None], axis=-1)))
    if not span > 0:
        raise rd.fail(
            "[mechanism].reference_length",
            "all joint anchors coincide; give a positive reference_length",
        )
    return span


def _read_lengths(rd, data, joint_index, scale):
    """``[[lengths]]``: pairs of distinct joints and their positive distance."""
    items = rd.entries(data, "lengths", required=False)
    pairs, values, labels, seen = [], [], [], {}
    for k, item in enumerate(items):
        where = f"lengths[{k}]"
        rd.keys(item, where, {"joints", "length"}, {"joints", "length"})
        names = item["joints"]
        if not isinstance(names, list) or len(names) != 2:
            raise rd.fail(
                f"{where}.joints",
                f"expected a list of two joint names, got {shown(names)}",
            )
        pair = tuple(
            rd.lookup(joint_index, n, f"{where}.joints", "joint") for n in names
        )
        if pair[0] == pair[1]:
            raise rd.fail(f"{where}.joints", "expected two different joints")
        key = frozenset(pair)
        if key in seen:
            raise rd.fail(
                f"{where}.joints",
                f"the distance {names[0]}–{names[1]} is already declared by "
                f"lengths[{seen[key]}]",
            )
        seen[key] = k
        length = rd.positive(item, "length", where)
        pairs.append(pair)
        values.append(length / scale)
        labels.append(
            (where, tuple(names), f"{names[0]}–{names[1]} = {length:g}", pair)
        )
    arrays = (np.array(pairs, dtype=int).reshape(-1, 2), np.array(values, dtype=float))
    return arrays, labels


def _local_rows(frames, scale, joints, pairs, ground):
    """One 3-row block per local anchor: ``a_j = p_b + R_b ℓ_bj``; but for the body
    that slides on a prismatic or cylindrical joint (:func:`.lines.line_rows`)."""
    frame, joint, at, labels = [], [], [], []
    for f_index, f in enumerate(frames):
        for j, local in f["anchors"].items():
            if slides_on(joints[j], pairs[j], f["body"], ground):
                continue
            frame.append(f_index)
            joint.append(j)
            at.append(local / scale)
            name = joints[j]["name"]
            where = anchor_field(f, j, joints)
            labels.append((where, (), f"the local anchor of {name}", (j,)))
    arrays = (
        np.array(frame, dtype=int),
        np.array(joint, dtype=int),
        np.array(at, dtype=float).reshape(-1, 3),
    )
    return arrays, [lab for lab in labels for _ in range(3)]
