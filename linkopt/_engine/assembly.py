"""Assembly: a mechanism file from approximate anchors and declared dimensions.

A file may describe its mechanism the way a drawing does, and let linkopt solve the
loop closures (issue 20, part 1):

* ``[[lengths]]``: ``joints = ["a", "b"]`` and ``length = 40.0``, the distance between
  two joint anchors (file units), held exactly;
* a body in its own frame: ``frame = [x, y, z]`` (approximate world position of the
  body frame at rest), optional ``orientation = [w, x, y, z]`` (unit quaternion, body
  to world, identity by default), ``anchors = { joint = [x, y, z], ... }``, the
  anchors of *all* its joints in that frame (as MJCF/URDF bodies), held exactly, and
  optional ``axes = { joint = [x, y, z], ... }``, joint axes in that frame;
* ``[mechanism].assemble = true`` asks the loader to assemble before reading the file,
  so every command uses such a file directly; ``linkopt assemble`` writes the result.

What is solved (choices the issue leaves open, made here):

* Unknowns are the world anchors of the joints at the rest pose, plus the pose
  (position, rotation vector) of each body given in its own frame. The anchors of
  joints on the ground are the world frame: they are held where written, and a
  declared length between two of them must already hold.
* A body in its own frame is rigid and carries its joint axes: an axis in its
  ``axes`` is in its frame, one written in ``[[joints]]`` is the world direction at
  the body's drawn pose; both turn with the body. The ground and a body given by world
  anchors hold their axes as written. Each joint keeps its carriers' axes together:
  parallel (two rows) for a revolute, prismatic or cylindrical joint, perpendicular
  (one row) for a universal joint's ``axis`` and ``axis2``. So a spatial loop of
  bodies in their own frames (a spherical five-bar) closes with its moving axes
  turned. A body given by world anchors is held together only by the declared lengths
  (fine for a planar loop, where every anchor stays in its plane); give the bodies of a
  spatial mechanism in their own frames, and a slider too (its rail anchor on the
  ground is held, so a slider in its own frame stays where that anchor is written).
* Each motor is held at its drawn value: a rotary motor keeps the angle about its axis
  (as its first body carries it) between the anchor of its second body farthest from
  the axis and that of its first body (a fixed world direction when the first body is
  the ground); a linear motor keeps the offset along its axis. ``motors``
  (``--motors``) turns them by these values (rad, file units) from the drawing before
  assembling. The assembled rest pose then *defines* motor zero, as for every file
  (motors are measured from the rest pose).
* Of the assemblies that hold all of that, the one that moves the anchors least:
  ``min Σ_j |a_j - a_j⁰|² (+ 10⁻² Σ_b |Δframe_b|², rotations in rad, lengths in
  reference lengths)``. It is found from the drawing (so the drawing chooses the
  assembly branch) by Levenberg–Marquardt with minimum-norm steps (every step the
  least squares step of least weighted length), then Gauss–Newton projections onto the
  nearest point of the constraint manifold (``dy = -(I - J⁺J) (y - y⁰) - J⁺ r``, whose
  fixed points are the first-order optimality conditions), then a last polish.
  Written here rather than with optimistix (as :mod:`.lm` is): neither step is one of
  its least-squares solvers, and the problems are tiny (tens of unknowns).
* A file whose loops cannot close is refused, never changed silently: the message
  names the loop (its joints and bodies, a fundamental cycle of the body graph through
  the joints that miss), the dimensions that cannot all hold at the closest assembly
  (the least squares minimum from the drawing), the gap, the sum of their misses in
  file units (for a single loop pulled straight that is the amount by which it fails
  to close) and the axes' miss in degrees, and which of the loop's axes are held as
  written. Where the loops close only with the motors free, the message says so.
* Points given by ``position`` move with their body. On a body given in its own
  frame the position is in that frame, like the body's anchors, and follows the
  assembled frame exactly; on a body given by world anchors it is a world position
  at rest, carried by the best-fit rigid motion of the body's anchors (a body whose
  anchors are collinear turns by the smallest rotation that aligns them).

Without ``assemble = true``, declared ``[[lengths]]`` are checked against the anchors
(to :data:`CHECK_TOL` reference lengths), so a hand-solved file can state them; a body
in its own frame needs ``assemble = true``. The assembled definition has world anchors
and axes only (no ``[[lengths]]``, frames or ``assemble``), so that it, and every design
written from it, is an ordinary file.
"""

from __future__ import annotations

import copy
import functools
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
from jaxtyping import Float

from .._config import jit
from .fields import Reader, field_name, is_number_list, shown
from .model import MOTOR_JOINTS

#: Frame variables (position and rotation vector) weigh this in the movement norm,
#: against 1 for anchors: a frame moves freely but not for nothing (a body with two
#: anchors still has a definite rotation about their line).
FRAME_WEIGHT = 1e-2
#: max |residual| (reference lengths, rad) below which the loops are closed.
CLOSE_TOL = 1e-10
#: Declared lengths of a file that is not assembled hold to this (reference lengths).
CHECK_TOL = 1e-9
#: σ_min (homogenised) of the FK Jacobian at an assembled rest pose below which
#: ``linkopt assemble`` warns that the pose is near a singularity; the loader refuses
#: below :data:`linkopt._engine.mobility.SINGULAR_TOL` (1e-7). The shipped files' rest
#: poses have σ_min of 0.03-0.3 (FK and BK), and f_sing is above 1000 below it.
NEAR_SINGULAR = 1e-3
#: Iteration caps: minimum-norm LM, projection onto the nearest assembly.
LM_ITERATIONS = 400
PROJECTION_ITERATIONS = 100
BODY_KEYS = ("frame", "orientation", "anchors", "axes")
#: Joint kinds whose one axis both bodies carry (their axes stay parallel).
SHARED_AXIS = ("revolute", "prismatic", "cylindrical")


class Rows(NamedTuple):
    """The constraint rows of an assembly (homogenised), as arrays (a pytree).

    ``J`` joints, ``F`` bodies in their own frame, ``N`` lengths, ``R`` local anchors,
    ``A`` axis rows, ``M`` held motors. A vector carried by frame ``f`` turns with the
    frame's turn from the drawing; a held one (``-1``) stays as written.
    """

    pairs: np.ndarray  # (N, 2) int joint indices
    lengths: np.ndarray  # (N,)
    local_frame: np.ndarray  # (R,) int frame index
    local_joint: np.ndarray  # (R,) int joint index
    local_at: np.ndarray  # (R, 3) anchor in the body frame
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


class Axis(NamedTuple):
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
    rows: Rows
    row_labels: tuple[tuple[str, tuple[str, ...], str], ...]  # (where, joints, text)
    row_joints: tuple[tuple[int, ...], ...]  # per row, the joints it concerns
    axes: tuple[Axis, ...]  # the joint axes bodies carry
    pairs: tuple[tuple[int, int], ...]  # per joint, its two bodies
    body_names: tuple[str, ...]
    ground: int
    declared: tuple[float, ...]  # the lengths as written (file units)
    motor_names: tuple[str, ...]
    scale: float
    units: str


@dataclass(frozen=True)
class Move:
    """How far one joint anchor moved (file units)."""

    joint: str
    before: tuple[float, float, float]
    after: tuple[float, float, float]
    distance: float


@dataclass(frozen=True)
class Report:
    """What an assembly did: the moves, the declared lengths as achieved, the largest
    constraint residual left (file units for lengths) and the iteration counts."""

    moves: tuple[Move, ...]
    lengths: tuple[tuple[tuple[str, str], float, float], ...]  # (pair, declared, got)
    residual: float
    iterations: int
    units: str

    @property
    def largest_move(self) -> float:
        return max((m.distance for m in self.moves), default=0.0)


@dataclass(frozen=True)
class Assembled:
    """The assembled definition (world anchors, an ordinary file) and its report."""

    data: dict
    report: Report


def requested(data: dict) -> bool:
    """``[mechanism].assemble = true``."""
    head = data.get("mechanism")
    return isinstance(head, dict) and head.get("assemble") is True


def prepare(data: dict, source: str) -> dict:
    """The loader's hook: the definition to read. Assembled on request, checked and
    stripped of ``[[lengths]]`` otherwise; unchanged when it declares nothing."""
    declares = "lengths" in data or (
        isinstance(data.get("mechanism"), dict) and "assemble" in data["mechanism"]
    )
    if not declares and not _frame_bodies(data):
        return data
    rd = Reader(source)
    head = data.get("mechanism")
    if isinstance(head, dict) and "assemble" in head:
        rd.boolean(head, "assemble", "[mechanism]")
    if requested(data):
        return assemble(data, source).data
    if _frame_bodies(data):
        k = _frame_bodies(data)[0]
        raise rd.fail(
            f"bodies[{k}].anchors",
            "a body given in its own frame needs [mechanism].assemble = true",
        )
    problem = read_problem(data, source)
    _check_declared(rd, problem)
    return _strip(data)


def assemble(data: dict, source: str, motors=None) -> Assembled:
    """Assemble a parsed definition: the assembled definition and the report.

    ``motors`` (``(M,)``, rad or file units, optional) turns the motors by these values
    from the drawing first. :class:`MechanismFileError` for bad fields and for loops
    that do not close."""
    problem = read_problem(data, source, motors)
    x0 = _start(problem)
    x, residual, iterations = _solve(problem, x0, problem.rows)
    if residual > CLOSE_TOL:
        _refuse(Reader(source), problem, x0, x)
    return Assembled(
        _written(data, problem, x), _report(problem, x, residual, iterations)
    )


# --- reading ------------------------------------------------------------------------


def _frame_bodies(data: dict) -> list[int]:
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
    scale = _scale(rd, head, anchors0)
    lengths, length_labels = _read_lengths(rd, data, joint_index, scale)
    local, local_labels = _local_rows(frames, scale, joints)
    axes = _read_axes(rd, frames, joints, pairs)
    axis_rows, axis_labels = _axis_rows(axes, joints)
    motor_rows, motor_names, motor_labels = _read_motors(
        rd, data, joints, joint_index, pairs, anchors0, ground, scale, motors, axes
    )
    rows = Rows(
        pairs=lengths[0],
        lengths=lengths[1],
        local_frame=local[0],
        local_joint=local[1],
        local_at=local[2],
        rotation0=np.array([f["rotation"] for f in frames]).reshape(-1, 3, 3),
        **axis_rows,
        **motor_rows,
    )
    labels = length_labels + local_labels + axis_labels + motor_labels
    return Problem(
        joint_names=tuple(j["name"] for j in joints),
        drawn=anchors0,
        anchors0=anchors0 / scale,
        held=np.array([ground in p for p in pairs], dtype=bool),
        frame_names=tuple(bodies[f["body"]]["name"] for f in frames),
        frame_bodies=tuple(f["body"] for f in frames),
        frames0=np.array([f["origin"] for f in frames]).reshape(-1, 3) / scale,
        rows=rows,
        row_labels=tuple(lab[:3] for lab in labels),
        row_joints=tuple(lab[3] for lab in labels),
        axes=axes,
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
    for k in _frame_bodies({"bodies": bodies}):
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
        if _axis_key(joints[joint], pairs[joint], k) is None:
            raise rd.fail(
                f"{where}.axes",
                f"joint {name!r} is {shown(joints[joint].get('type'))}: it has no "
                "axis for a body to carry",
            )
        local[joint] = rd.direction(table, name, f"{where}.axes")
    return local


def _drawn_anchors(rd, joints, pairs, frames, ground) -> Float[np.ndarray, "J 3"]:
    """Each joint's drawn world anchor: ``anchor``, or where the frames of its bodies
    put it (their mean). A joint whose both bodies give it in their frames has no
    ``anchor`` (it would be given twice); every other joint needs one."""
    images: dict[int, list[np.ndarray]] = {}
    for f in frames:
        for joint, at in f["anchors"].items():
            images.setdefault(joint, []).append(f["origin"] + f["rotation"] @ at)
    anchors = np.zeros((len(joints), 3))
    for k, joint in enumerate(joints):
        where, given = f"joints[{k}]", "anchor" in joint
        if given and len(images.get(k, [])) == 2:
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
        elif k in images:
            anchors[k] = np.mean(images[k], axis=0)
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


def _local_rows(frames, scale, joints):
    """One 3-row block per local anchor: ``a_j = p_b + R_b ℓ_bj``."""
    frame, joint, at, labels = [], [], [], []
    for f_index, f in enumerate(frames):
        for j, local in f["anchors"].items():
            frame.append(f_index)
            joint.append(j)
            at.append(local / scale)
            name = joints[j]["name"]
            where = f"bodies[{f['body']}].anchors.{field_name(name)}"
            labels.append((where, (), f"the local anchor of {name}", (j,)))
    arrays = (
        np.array(frame, dtype=int),
        np.array(joint, dtype=int),
        np.array(at, dtype=float).reshape(-1, 3),
    )
    return arrays, [lab for lab in labels for _ in range(3)]


def _read_axes(rd, frames, joints, pairs) -> tuple[Axis, ...]:
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


def _axis_rows(axes: tuple[Axis, ...], joints):
    """Rows ``p · q = 0`` that keep the carriers of each axis together: two for a
    shared axis (``q`` ⟂ two normals ``p`` of the first carrier: parallel), one for a
    universal joint (its two axes perpendicular). None where no carrier moves."""
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
            u = _any_normal(vp)
            pairs = [(u, vq), (np.cross(vp, u), vq)]
            text = f"the {axis.key} of {name}"
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


def _partner(axes: tuple[Axis, ...], axis: Axis) -> Axis | None:
    """A universal joint's ``axis2`` given its ``axis`` (None if not given)."""
    return next((a for a in axes if a.joint == axis.joint and a.key == "axis2"), None)


def _axis_key(joint: dict, pair, body: int) -> str | None:
    """The axis field of ``joint`` that ``body`` carries, if any."""
    kind = joint.get("type")
    if kind in SHARED_AXIS:
        return "axis"
    if kind == "universal":
        return "axis" if pair[0] == body else "axis2"
    return None


def _read_motors(
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
    fields = {key: [] for key in Rows._fields if key.startswith("motor_")}
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
    line (rotary) or point (linear); -1 when none is off it."""
    best, best_d = -1, 1e-9
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
    e = e / np.linalg.norm(e) if np.linalg.norm(e) > 1e-9 else _any_normal(axis)
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


def _any_normal(axis: np.ndarray) -> np.ndarray:
    helper = np.eye(3)[int(np.argmin(np.abs(axis)))]
    e = helper - (helper @ axis) * axis
    return e / np.linalg.norm(e)


# --- solving ------------------------------------------------------------------------


def _start(problem: Problem) -> np.ndarray:
    """Drawn anchors, then the drawn frames (position, zero rotation vector)."""
    frames = np.concatenate(
        [problem.frames0, np.zeros_like(problem.frames0)], axis=1
    ).ravel()
    return np.concatenate([problem.anchors0.ravel(), frames])


def _weights(problem: Problem) -> np.ndarray:
    """Per variable, the square root of its inverse weight in the movement norm; zero
    for held anchors."""
    anchors = np.repeat(np.where(problem.held, 0.0, 1.0), 3)
    frames = np.full(6 * len(problem.frame_names), FRAME_WEIGHT**-0.5)
    return np.concatenate([anchors, frames])


def _solve(problem: Problem, x0: np.ndarray, rows: Rows):
    """Assemble from ``x0``: (x, max |residual|, iterations)."""
    lm, project, _ = _programs()
    sizes = (len(problem.joint_names), len(problem.frame_names))
    s = _weights(problem)
    x, first = lm(sizes, rows, x0, s)
    residual = float(np.max(np.abs(_residual_np(sizes, rows, x)), initial=0.0))
    if residual <= CLOSE_TOL and len(x):
        y, steps = project(sizes, rows, x, x0, s)
        y, polish = lm(sizes, rows, y, s)
        after = float(np.max(np.abs(_residual_np(sizes, rows, y)), initial=0.0))
        if after <= CLOSE_TOL and _moved(y, x0, s) <= _moved(x, x0, s) + 1e-12:
            return np.asarray(y), after, int(first) + int(steps) + int(polish)
    return np.asarray(x), residual, int(first)


def _moved(x, x0, s) -> float:
    return float(
        np.sum(np.where(s > 0, (np.asarray(x) - x0) / np.where(s > 0, s, 1), 0) ** 2)
    )


def _residual_np(sizes, rows, x) -> np.ndarray:
    return np.asarray(_programs()[2](sizes, rows, x))


def _rotation(omega):
    """Rotation matrices of rotation vectors ``(F, 3)`` (Rodrigues, finite at 0)."""
    import jax.numpy as jnp

    theta = jnp.sqrt(jnp.sum(omega**2, axis=-1) + 1e-300)[:, None, None]
    k = jnp.zeros(omega.shape[:-1] + (3, 3))
    k = k.at[:, 0, 1].set(-omega[:, 2]).at[:, 0, 2].set(omega[:, 1])
    k = k.at[:, 1, 0].set(omega[:, 2]).at[:, 1, 2].set(-omega[:, 0])
    k = k.at[:, 2, 0].set(-omega[:, 1]).at[:, 2, 1].set(omega[:, 0])
    a = jnp.sin(theta) / theta
    b = (1.0 - jnp.cos(theta)) / theta**2
    b = jnp.where(theta < 1e-8, 0.5, b)
    return jnp.eye(3) + a * k + b * (k @ k)


def _residual(sizes: tuple[int, int], rows: Rows, x):
    """Length rows, local-anchor rows (3 each), axis rows, motor rows; homogenised
    (rad for axes and rotary motors)."""
    import jax.numpy as jnp

    joints, frames = sizes
    a = x[: 3 * joints].reshape(joints, 3)
    pose = x[3 * joints :].reshape(frames, 6)
    d = a[rows.pairs[:, 0]] - a[rows.pairs[:, 1]]
    lengths = jnp.sqrt(jnp.sum(d * d, axis=-1) + 1e-300) - rows.lengths
    turn = _rotation(pose[:, 3:])
    rot = jnp.einsum("fij,fjk->fik", turn, rows.rotation0)
    image = pose[rows.local_frame, :3] + jnp.einsum(
        "rij,rj->ri", rot[rows.local_frame], rows.local_at
    )
    local = (a[rows.local_joint] - image).ravel()
    carry = jnp.concatenate([jnp.eye(3)[None], turn])  # index: frame + 1
    p = jnp.einsum("aij,aj->ai", carry[rows.axis_p + 1], rows.axis_vp)
    q = jnp.einsum("aij,aj->ai", carry[rows.axis_q + 1], rows.axis_vq)
    axes = jnp.sum(p * q, axis=-1)
    motors = _motor_residual(rows, a, carry[rows.motor_frame + 1])
    return jnp.concatenate([lengths, local, axes, motors])


def _motor_residual(rows: Rows, a, carry):
    """Held motors, about their axes as their first bodies carry them (``carry``
    ``(M, 3, 3)``: each first body's turn from the drawing)."""
    import jax.numpy as jnp

    def turned(v):
        return jnp.einsum("mij,mj->mi", carry, v)

    axis, e, f = turned(rows.motor_axis), turned(rows.motor_e), turned(rows.motor_f)
    pivot = a[rows.motor_joint]
    has_base = rows.motor_base >= 0
    base = a[jnp.maximum(rows.motor_base, 0)]
    v = a[rows.motor_moved] - pivot
    w = base - pivot

    def angle(u):
        return jnp.arctan2(jnp.sum(u * f, axis=-1), jnp.sum(u * e, axis=-1))

    turn = angle(v) - jnp.where(has_base, angle(w), 0.0) - rows.motor_target
    rotary = jnp.arctan2(jnp.sin(turn), jnp.cos(turn))
    ref = jnp.where(has_base[:, None], base, pivot)
    linear = jnp.sum((a[rows.motor_moved] - ref) * axis, -1)
    return jnp.where(rows.motor_linear, linear - rows.motor_target, rotary)


@functools.cache
def _programs():
    """The jitted solver stages (built on first use: parsing alone needs no JAX)."""
    import jax
    import jax.numpy as jnp

    from . import dense

    def scaled_jacobian(sizes, rows, x, s):
        r = _residual(sizes, rows, x)
        jac = jax.jacfwd(lambda y: _residual(sizes, rows, y))(x) * s[None, :]
        return r, jac

    def min_norm(jac, rhs, damping):
        """``Jᵀ (J Jᵀ + μ I)⁻¹ rhs``: the least-norm (damped) ``d`` of ``J d = rhs``."""
        gram = jac @ jac.T
        eye = jnp.eye(gram.shape[0])
        return jac.T @ dense.solve(gram + damping * eye, rhs)

    @functools.partial(jit, static_argnums=0)
    def lm(sizes, rows, x, s):
        """Levenberg–Marquardt with least-norm steps; accepts only decreasing steps."""

        def body(state):
            x, mu, it, _ = state
            r, jac = scaled_jacobian(sizes, rows, x, s)
            dx = -s * min_norm(jac, r, mu)
            r_new = _residual(sizes, rows, x + dx)
            better = jnp.sum(r_new**2) < jnp.sum(r**2)
            small = jnp.max(jnp.abs(dx)) < 1e-16 * (1.0 + jnp.max(jnp.abs(x)))
            done = (jnp.max(jnp.abs(jnp.where(better, r_new, r))) < 1e-15) | (
                ~better & ((mu > 1e12) | small)
            )
            mu = jnp.where(better, jnp.maximum(mu / 3.0, 1e-15), mu * 4.0)
            return jnp.where(better, x + dx, x), mu, it + 1, done

        def cond(state):
            return (~state[3]) & (state[2] < LM_ITERATIONS)

        start = (x, jnp.asarray(1e-6), jnp.asarray(0), jnp.asarray(x.size == 0))
        x, _, it, _ = jax.lax.while_loop(cond, body, start)
        return x, it

    @functools.partial(jit, static_argnums=0)
    def project(sizes, rows, x, x0, s):
        """Gauss–Newton projection onto the assembly nearest the drawing."""

        def body(state):
            x, it, _ = state
            r, jac = scaled_jacobian(sizes, rows, x, s)
            delta = jnp.where(s > 0, (x - x0) / jnp.where(s > 0, s, 1.0), 0.0)
            dy = -delta + min_norm(jac, jac @ delta - r, 1e-14)
            dx = s * dy
            small = jnp.max(jnp.abs(dx)) < 1e-15
            return x + dx, it + 1, small

        def cond(state):
            return (~state[2]) & (state[1] < PROJECTION_ITERATIONS)

        x, it, _ = jax.lax.while_loop(
            cond, body, (x, jnp.asarray(0), jnp.asarray(False))
        )
        return x, it

    residual = jit(_residual, static_argnums=0)
    return lm, project, residual


# --- refusing -----------------------------------------------------------------------


def _refuse(rd: Reader, problem: Problem, x0, x) -> None:
    """The loops do not close from the drawing: say which loop, which dimensions and
    by how much, and which axes are held (module docstring); with motors held, first
    whether freeing them would close."""
    free = _without_motors(problem.rows)
    if len(problem.motor_names):
        y, residual, _ = _solve(problem, x0, free)
        if residual <= CLOSE_TOL:
            names = ", ".join(repr(n) for n in problem.motor_names)
            raise rd.fail(
                "[[motors]]",
                f"the loops close, but not with motor(s) {names} held at their drawn "
                "values (plus --motors): choose motor values the mechanism can reach, "
                "or draw it closer to an assembly",
            )
        x = y
    sizes = (len(problem.joint_names), len(problem.frame_names))
    r = _residual_np(sizes, free, x)
    missing = np.abs(r) > max(1e-3 * float(np.max(np.abs(r))), CLOSE_TOL)
    rows = np.flatnonzero(missing)
    labels = [problem.row_labels[k] for k in rows]
    gap, angle = _misses(r, missing, problem.rows)
    gap *= problem.scale
    missed = sorted({j for k in rows for j in problem.row_joints[k]})
    joints, bodies, count = _loop(problem, missed)
    dims = _dimensions(problem, rows)
    turned = f" and its axes by {angle:.3g}°" if angle > 0 else ""
    raise rd.fail(
        labels[0][0] if labels else "[[lengths]]",
        f"the loop{'s' if count > 1 else ''} through joints "
        f"{', '.join(problem.joint_names[j] for j in joints)} (bodies "
        f"{', '.join(problem.body_names[b] for b in bodies)}) does not close: {dims} "
        f"cannot all hold; the closest assembly misses by {gap:.6g} {problem.units}"
        f"{turned} in all{_held_axes(problem, joints)}",
    )


def _dimensions(problem: Problem, missing: np.ndarray) -> str:
    """What cannot all hold, from the rows that miss: declared lengths as written, the
    bodies whose part drawings (anchors in their frames) miss, the joints whose axes
    miss."""
    rows = problem.rows
    n, count = len(rows.lengths), 3 * len(rows.local_joint)
    texts = [problem.row_labels[k][2] for k in missing if k < n]
    parts = {
        problem.frame_names[rows.local_frame[(k - n) // 3]]
        for k in missing
        if n <= k < n + count
    }
    axes = {problem.row_joints[k][0] for k in missing if k >= n + count}
    if parts:
        names = ", ".join(b for b in problem.frame_names if b in parts)
        frames = "its frame" if len(parts) == 1 else "their frames"
        texts.append(f"the anchors of {names} in {frames}")
    if axes:
        names = ", ".join(problem.joint_names[j] for j in sorted(axes))
        texts.append(f"the axes of {names}")
    return "; ".join(dict.fromkeys(texts))


def _without_motors(rows: Rows) -> Rows:
    return rows._replace(
        **{k: getattr(rows, k)[:0] for k in Rows._fields if k.startswith("motor_")}
    )


def _misses(r, missing, rows: Rows) -> tuple[float, float]:
    """The gap in reference lengths (|length - declared| per missing length row, the
    distance per local anchor, its 3 rows together) and the axes' miss in degrees
    (the angle per axis row)."""
    n, count = len(rows.lengths), 3 * len(rows.local_joint)
    lengths = np.abs(r[:n]) * missing[:n]
    local = np.linalg.norm(r[n : n + count].reshape(-1, 3), axis=1)
    axes = np.abs(r[n + count : n + count + len(rows.axis_p)])
    angle = np.degrees(np.arcsin(np.minimum(axes, 1.0)))
    return float(np.sum(lengths) + np.sum(local)), float(np.sum(angle))


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


def _check_declared(rd: Reader, problem: Problem) -> None:
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


# --- writing ------------------------------------------------------------------------


def _strip(data: dict) -> dict:
    """The definition without what only assembly reads."""
    out = copy.deepcopy(data)
    out.pop("lengths", None)
    if isinstance(out.get("mechanism"), dict):
        out["mechanism"].pop("assemble", None)
    return out


def _written(data: dict, problem: Problem, x: np.ndarray) -> dict:
    """The assembled definition: world anchors at full precision, frames resolved."""
    out = _strip(data)
    count = len(problem.joint_names)
    anchors = _assembled_anchors(problem, x)
    poses = x[3 * count :].reshape(-1, 6)
    for k, joint in enumerate(out["joints"]):
        _set_anchor(joint, anchors[k])
    rotations = _frame_rotations(problem, poses)
    _set_axes(out, problem, rotations)
    for f, b in enumerate(problem.frame_bodies):
        body = out["bodies"][b]
        for key in BODY_KEYS:
            body.pop(key, None)
        body["origin"] = [float(v) for v in poses[f, :3] * problem.scale]
    _carry_points(out, problem, anchors, poses, rotations)
    return out


def _assembled_anchors(problem: Problem, x: np.ndarray) -> np.ndarray:
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
    turn = np.asarray(_rotation(jnp.asarray(poses[:, 3:])))
    return np.einsum("fij,fjk->fik", turn, problem.rows.rotation0)


def _carry_points(out, problem, anchors, poses, rotations) -> None:
    """Points given by ``position`` move with their body: on a body given in its own
    frame the position is in that frame (as its anchors are), on any other body it is
    a world position at rest, carried by the best-fit rigid motion of its anchors."""
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
        if b in frame_of:  # given in the body frame, as the body's anchors are
            f = frame_of[b]
            new = poses[f, :3] * scale + rotations[f] @ old
        else:
            on = [j for j in range(len(anchors)) if b in _bodies_of(out, j, names)]
            rot, before, after = _fit(problem.anchors0[on] * scale, anchors[on])
            new = after + rot @ (old - before)
        point["position"] = [float(v) for v in new]


def _bodies_of(out, j, names) -> tuple[int, ...]:
    return tuple(names.index(b) for b in out["joints"][j]["bodies"])


def _fit(before: np.ndarray, after: np.ndarray):
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
    """The smallest rotation taking unit ``u`` to unit ``v``."""
    axis, c = np.cross(u, v), float(u @ v)
    if c < -1 + 1e-12:
        n = _any_normal(u)
        return 2.0 * np.outer(n, n) - np.eye(3)
    k = np.array(
        [[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]]
    )
    return np.eye(3) + k + k @ k / (1.0 + c)


def _report(
    problem: Problem, x: np.ndarray, residual: float, iterations: int
) -> Report:
    after, before = _assembled_anchors(problem, x), problem.drawn
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
    return Report(
        moves, lengths, _geometric_residual(problem, x), iterations, problem.units
    )


def _geometric_residual(problem: Problem, x: np.ndarray) -> float:
    """Largest miss of a declared length or local anchor (file units)."""
    sizes = (len(problem.joint_names), len(problem.frame_names))
    count = len(problem.rows.lengths) + 3 * len(problem.rows.local_joint)
    r = _residual_np(sizes, problem.rows, x)[:count]
    return float(np.max(np.abs(r), initial=0.0)) * problem.scale
