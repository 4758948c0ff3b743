"""Mechanism definition files (TOML): parsing and validation, before any solving.

Every problem is reported as one :class:`MechanismFileError` naming the file, the
table/field and what was expected (through the shared :class:`~.fields.Reader`).
Nothing missing is silently replaced by a default; the only optional fields are those
documented in the README with their defaults (``reference_length``, ``[solver]``,
``axis`` of a fixed joint, ``[symmetry]``, ``[[parameters]]``, ``mirror``).

Every field is checked for its TOML type, and every number for being finite and of a
magnitude the solver can work with, before anything is computed from it, so that an
absurd value is named where it is written and never surfaces later as a wrong mobility
or a singular rest pose. The bounds (the constants below):

* the reference length ``L`` (given, or the span of the joint anchors) lies in
  [1e-12, 1e12] file units, and a given one within a factor 1e3 of the span: the
  solver works on lengths divided by ``L``, and the five-bar's rest check and FK still
  hold at ``L`` = 1e-4 to 1e4 times its span but not at 1e-6 or 1e6 (the rank and
  σ_min tests and the LM tolerance are absolute in homogenised units);
* every position (anchors, body origins, point positions, the symmetry point,
  Cartesian output ranges and anchor-parameter bounds) is at most 1e6 reference
  lengths and 1e12 file units from the world origin in each coordinate: far past any
  real layout (the five-bar still solves 1e8 reference lengths away), far below where
  squares of lengths overflow;
* angle-output ranges lie within ±1e3 rad, axis-parameter bounds within ±1e6 (the axis
  is normalised, so beyond that its direction no longer changes in float64);
* the ``[solver]`` and ``[evaluation]`` settings lie in :data:`SETTING_RANGES`, and a
  target grid has at most :data:`MAX_TARGETS` targets.

Axes and the symmetry normal are directions: any finite non-zero vector is one.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
from jaxtyping import Float

from .attachment import attach
from .design_space import read_design, read_symmetry
from .fields import (
    Reader,
    field_name,
    is_number_list,
    parse_text,
    parse_toml,
    shown,
)
from .links import read_collision
from .model import (
    AXIAL_JOINTS,
    JOINT_ROWS,
    MOTOR_JOINTS,
    OUTPUT_KINDS,
    EvaluationSettings,
    Mechanism,
    OutputTable,
    SolverSettings,
)

TOP_LEVEL = {
    "mechanism",
    "bodies",
    "joints",
    "motors",
    "points",
    "outputs",
    "symmetry",
    "parameters",
    "solver",
    "evaluation",
    "collision",
}
ORTHOGONAL_TOL = 1e-9
#: Smallest and largest reference length (file units).
REFERENCE_LENGTHS = (1e-12, 1e12)
#: A given reference length lies within this factor of the joint anchors' span.
SCALE_RATIO = 1e3
#: Largest coordinate of a position: in reference lengths, and in file units.
MAX_EXTENT = 1e6
MAX_COORDINATE = 1e12
#: Largest |bound| of an angle-output range (rad).
MAX_ANGLE = 1e3
#: ``[solver]`` and ``[evaluation]`` numbers: (smallest, largest). The LM tolerance is
#: on max |C| in homogenised units (float64 resolves ~1e-16 of a reference length); the
#: LM gives up at a damping of 1e12; a trust radius of 10 rad or reference lengths is
#: already past any single step.
SETTING_RANGES: dict[str, tuple[float, float]] = {
    "max_iterations": (1, 10_000),
    "tolerance": (1e-16, 1e-2),
    "initial_damping": (1e-16, 1e6),
    "samples_per_dimension": (2, 100),
    "alpha_factor": (1e-6, 1e6),
    "motion_weight": (1e-12, 1e6),
    "range_weight": (1e-12, 1e6),
    "regularizer_weight": (1e-12, 1e6),
    "max_step": (1e-9, 10.0),
    "ik_iterations": (1, 10_000),
    "adversarial_iterations": (1, 10_000),
    "alpha_minus": (1e-12, 1e12),
}
#: Most IK targets of an evaluation (the grid's and ``[evaluation].targets``).
MAX_TARGETS = 100_000
#: Most bodies of a mechanism (:func:`_check_size`): the solver works on dense square
#: matrices of 7 numbers per body, batched 64 at a time (``blocks.BLOCK``) with a few
#: copies each; at 300 bodies a block holds about 2 GB of them.
MAX_BODIES = 300
#: Matrices of a block of solves held at once in that estimate (64 rows, 3 copies).
BLOCK_COPIES = 64 * 3


def load(path: str | Path) -> Mechanism:
    """Read, validate and assemble a mechanism definition file."""
    path = Path(path)
    return build(parse_text(path), str(path))


def loads(text: str, source: str = "<string>") -> Mechanism:
    """As :func:`load`, from the text of a file."""
    return build(parse_toml(text, source), source)


def build(data: dict, source: str, check: bool = True) -> Mechanism:
    """Validate a parsed definition and build the :class:`Mechanism`; ``check=False``
    skips the mobility/rest-singularity check (for test geometry only)."""
    from .assembly import prepare  # [mechanism].assemble, [[lengths]], body frames

    rd = Reader(source)
    _check_size(rd, data)
    data = prepare(data, source)
    head = _read_head(rd, data)
    bodies, body_index = _read_bodies(rd, data)
    ground = rd.lookup(body_index, head["ground"], "[mechanism].ground", "body")
    joints = _read_joints(rd, data, body_index)
    anchors = np.array([j["anchor"] for j in joints])
    scale = _reference_length(rd, head, anchors)
    for k, joint in enumerate(joints):
        _check_position(rd, f"joints[{k}].anchor", joint["anchor"], scale)
    origins = _body_origins(rd, bodies, joints, ground, scale)
    points = _read_points(rd, data, body_index, joints, scale)
    motors = _read_motors(rd, data, joints)
    outputs, reported = _read_outputs(rd, data, points, joints, scale)
    symmetry = read_symmetry(
        rd, data, lambda t, key, at: _position(rd, t, key, at, scale)
    )
    design = read_design(
        rd, data, joints, body_index, symmetry, scale,
        lambda at, values: _check_position(rd, at, values, scale),
    )  # fmt: skip
    solver = _read_solver(rd, data)
    evaluation = _read_evaluation(rd, data, outputs, scale)
    mech = Mechanism(
        name=head["name"],
        source=source,
        **_body_fields(bodies, ground, origins),
        **_joint_fields(joints, anchors),
        **_point_fields(points, joints, anchors, scale),
        **_motor_fields(motors),
        **_output_fields(outputs, reported),
        design=design,
        length_scale=scale,
        solver=solver,
        evaluation=evaluation,
        symmetry=symmetry,
        raw=data,
        **idle_spins(joints, points, outputs + reported, ground, len(bodies), scale),
    )
    collision = read_collision(rd, mech)  # [collision], bodies' radius and layer
    if collision is not None:
        mech = dataclasses.replace(mech, collision=collision)
    if check:
        from .mobility import check_mobility  # needs JAX; kept out of pure parsing

        check_mobility(mech)
    return mech


#: Largest distance of a named point from an idle body's axis, in reference lengths.
IDLE_TOL = 1e-9


def idle_spins(
    joints: list[dict],
    points: list[dict],
    outputs: list[dict],
    ground: int,
    num_bodies: int,
    scale: float,
) -> dict:
    """The ``idle_bodies`` / ``idle_joints`` fields: bodies whose spin about their own
    axis moves no other body and no output (issue 20, part 4).

    Structural test, at load: a body other than the ground is idle when it has exactly
    two joints, both spherical, at distinct anchors (a rod between two ball joints, as
    in a Clavel delta), none of its named points lies off the line through them
    (farther than :data:`IDLE_TOL` reference lengths), and no output reads its
    orientation (an orientation output of the body or an angle of one of its joints).
    Motors never touch it (they drive revolute or prismatic joints). A point given on
    the axis stays on it only while the design keeps it there; off it, the point
    follows the gauge (the rod turned without twist). A body with three
    or more collinear ball joints is left alone: a design parameter could move them
    off their line and make the spin a real constraint. A body with one ball joint
    only (a free pendulum) has three idle freedoms, not handled: mobility then counts
    them and the load fails with the mobility message.
    """
    idle, pairs = [], []
    for body in range(num_bodies):
        mine = [k for k, j in enumerate(joints) if body in j["bodies"]]
        if body == ground or len(mine) != 2:
            continue
        if any(joints[k]["type"] != "spherical" for k in mine):
            continue
        start, end = (np.asarray(joints[k]["anchor"], dtype=float) for k in mine)
        if np.linalg.norm(end - start) <= IDLE_TOL * scale:
            continue
        if _sees_spin(body, mine, start, end, points, outputs, scale):
            continue
        idle.append(body)
        pairs.append(mine)
    return {
        "idle_bodies": np.array(idle, dtype=int),
        "idle_joints": np.array(pairs, dtype=int).reshape(-1, 2),
    }


def _sees_spin(body, mine, start, end, points, outputs, scale) -> bool:
    """Whether a named point off the axis ``start``-``end`` or an output of ``body``
    would move with its spin."""
    axis = (end - start) / np.linalg.norm(end - start)
    for p in points:
        if p["body"] == body:
            offset = np.asarray(p["position"], dtype=float) - start
            if np.linalg.norm(offset - (offset @ axis) * axis) > IDLE_TOL * scale:
                return True
    return any(o["joint"] in mine or body in o["bodies"] for o in outputs)


def _check_size(rd: Reader, data: dict) -> None:
    """Refuse, before any work, a mechanism too large for the dense linear algebra:
    the state has 7 numbers per body and every solve factors its square."""
    bodies = data.get("bodies")
    if not isinstance(bodies, list) or len(bodies) <= MAX_BODIES:
        return
    size = 7 * len(bodies)
    matrix = 8.0 * size * size
    raise rd.fail(
        "[[bodies]]",
        f"{len(bodies)} bodies make a state of {size} numbers: every solve factors "
        f"a {size} x {size} matrix ({matrix / 2**20:.0f} MB, about "
        f"{BLOCK_COPIES * matrix / 2**30:.0f} GB for a block of solves); linkopt's "
        f"dense solver takes at most {MAX_BODIES} bodies",
    )


def _read_head(rd: Reader, data: dict) -> dict:
    """The known top-level tables and the ``[mechanism]`` table."""
    rd.top_level(data, TOP_LEVEL)
    if "mechanism" not in data:
        raise rd.fail("[mechanism]", "missing table")
    head = rd.table(
        data["mechanism"],
        "[mechanism]",
        {"name", "ground", "reference_length", "units"},
        {"name", "ground"},
    )
    rd.string(head, "name", "[mechanism]")
    if "units" in head:
        rd.string(head, "units", "[mechanism]")
    return head


def _read_bodies(rd: Reader, data: dict) -> tuple[list[dict], dict[str, int]]:
    bodies = rd.entries(data, "bodies", required=True)
    body_index = rd.names(bodies, "bodies")
    for k, body in enumerate(bodies):
        rd.keys(body, f"bodies[{k}]", {"name", "origin", "radius", "layer"}, {"name"})
    return bodies, body_index


def _body_fields(bodies: list[dict], ground: int, origins: np.ndarray) -> dict:
    return {
        "body_names": tuple(b["name"] for b in bodies),
        "ground": ground,
        "body_origins": origins,
    }


def _joint_fields(joints: list[dict], anchors: np.ndarray) -> dict:
    pairs = np.array([j["bodies"] for j in joints], dtype=int).reshape(-1, 2)
    axes = np.array([j["axis"] for j in joints]).reshape(-1, 3)
    return {
        "joint_names": tuple(j["name"] for j in joints),
        "joint_types": tuple(j["type"] for j in joints),
        "joint_bodies": pairs,
        "anchors": anchors,
        "axes": axes,
        "axes2": np.array([j["axis2"] for j in joints]),
        "axis_present": np.linalg.norm(axes, axis=1) > 0,
        "helper_index": np.argmin(np.abs(axes), axis=1),
    }


def _point_fields(
    points: list[dict], joints: list[dict], anchors: np.ndarray, scale: float
) -> dict:
    positions = np.array([p["position"] for p in points]).reshape(-1, 3)
    on_body = [
        np.array([k for k, j in enumerate(joints) if p["body"] in j["bodies"]])
        for p in points
    ]
    follows = np.array([p["joint"] for p in points], dtype=int)
    return {
        "point_names": tuple(p["name"] for p in points),
        "point_bodies": np.array([p["body"] for p in points], dtype=int),
        "point_joints": follows,
        "point_positions": positions,
        "point_attachment": attach(anchors, on_body, positions, follows, scale),
    }


def _motor_fields(motors: list[dict]) -> dict:
    return {
        "motor_names": tuple(m["name"] for m in motors),
        "motor_joints": np.array([m["joint"] for m in motors], dtype=int),
        "motor_linear": np.array([m["linear"] for m in motors], dtype=bool),
    }


def _output_fields(outputs: list[dict], reported: list[dict] = ()) -> dict:
    """The Mechanism fields of the BK ``outputs`` and of the ``reported`` ones."""
    return {
        "output_names": tuple(o["name"] for o in outputs),
        "output_kinds": tuple(o["kind"] for o in outputs),
        "output_points": np.array([o["point"] for o in outputs], dtype=int),
        "output_coords": np.array([o["coord"] for o in outputs], dtype=int),
        "output_joints": np.array([o["joint"] for o in outputs], dtype=int),
        "output_min": np.array([o["min"] for o in outputs], dtype=float),
        "output_max": np.array([o["max"] for o in outputs], dtype=float),
        "output_bodies": _output_table(outputs).bodies,
        "output_frames": _output_table(outputs).frames,
        "reported": _output_table(list(reported)),
    }


def _output_table(outputs: list[dict]) -> OutputTable:
    return OutputTable(
        names=tuple(o["name"] for o in outputs),
        kinds=tuple(o["kind"] for o in outputs),
        points=np.array([o["point"] for o in outputs], dtype=int),
        coords=np.array([o["coord"] for o in outputs], dtype=int),
        joints=np.array([o["joint"] for o in outputs], dtype=int),
        bodies=np.array([o["bodies"] for o in outputs], dtype=int).reshape(-1, 2),
        frames=np.array([o["frame"] for o in outputs], dtype=float).reshape(-1, 2, 3),
    )


def _position_limit(scale: float | None) -> tuple[float, str]:
    """The largest coordinate of a position (file units) and how it is worded; before
    the reference length is known (``None``), the absolute bound alone."""
    if scale is None:
        return MAX_COORDINATE, f"{MAX_COORDINATE:g} file units"
    limit = min(MAX_COORDINATE, MAX_EXTENT * scale)
    return limit, (
        f"{limit:g} file units ({MAX_EXTENT:g} reference lengths of {scale:g}, "
        f"at most {MAX_COORDINATE:g})"
    )


def _check_position(rd: Reader, where: str, values, scale: float | None) -> None:
    """Coordinates (a number or a vector, file units) within the position bound."""
    limit, words = _position_limit(scale)
    largest = float(np.max(np.abs(values)))
    if largest > limit:
        raise rd.fail(
            where, f"expected coordinates of magnitude at most {words}, got {largest:g}"
        )


def _position(
    rd: Reader, item: dict, key: str, where: str, scale: float | None
) -> Float[np.ndarray, " 3"]:
    """``item[key]``: a position, 3 finite numbers within the position bound."""
    vec = rd.vector(item, key, where)
    _check_position(rd, f"{where}.{key}", vec, scale)
    return vec


def _read_joints(rd: Reader, data: dict, body_index: dict[str, int]) -> list[dict]:
    items = rd.entries(data, "joints", required=True)
    rd.names(items, "joints")
    return [
        _read_joint(rd, item, f"joints[{k}]", body_index)
        for k, item in enumerate(items)
    ]


def _read_joint(rd: Reader, item: dict, where: str, body_index: dict[str, int]) -> dict:
    rd.keys(
        item,
        where,
        {"name", "type", "bodies", "anchor", "axis", "axis2"},
        {"name", "type", "bodies", "anchor"},
    )
    kind = item["type"]
    if not isinstance(kind, str):
        raise rd.fail(
            f"{where}.type",
            f"expected a joint type string, one of {list(JOINT_ROWS)}, got "
            f"{shown(kind)}",
        )
    if kind not in JOINT_ROWS:
        raise rd.fail(
            f"{where}.type",
            f"unknown joint type {shown(kind)}; expected one of {list(JOINT_ROWS)}",
        )
    pair = _joint_bodies(rd, item, where, body_index)
    axis = _first_axis(rd, item, where, kind)
    axis2 = _second_axis(rd, item, where, kind, axis)
    return {
        "name": item["name"],
        "type": kind,
        "bodies": pair,
        "anchor": _position(rd, item, "anchor", where, None),
        "axis": axis,
        "axis2": axis2,
    }


def _joint_bodies(
    rd: Reader, item: dict, where: str, body_index: dict[str, int]
) -> tuple[int, int]:
    """The indices of the two different bodies a joint connects."""
    pair = item["bodies"]
    if not isinstance(pair, list) or len(pair) != 2:
        raise rd.fail(
            f"{where}.bodies",
            f"expected a list of two body names, got {shown(pair)}",
        )
    bi = rd.lookup(body_index, pair[0], f"{where}.bodies", "body")
    bj = rd.lookup(body_index, pair[1], f"{where}.bodies", "body")
    if bi == bj:
        raise rd.fail(
            f"{where}.bodies",
            f"a joint must connect two different bodies, got {shown(pair)}",
        )
    return bi, bj


def _first_axis(
    rd: Reader, item: dict, where: str, kind: str
) -> Float[np.ndarray, " 3"]:
    """``axis``: required for axial joints, ``z`` by default for a fixed one, and for
    a spherical joint part of an optional frame for its angle outputs (else zero)."""
    if kind in AXIAL_JOINTS:
        if "axis" not in item:
            raise rd.fail(f"{where}.axis", f"missing required field for a {kind} joint")
        return rd.direction(item, "axis", where)
    if kind == "fixed":
        if "axis" in item:
            return rd.direction(item, "axis", where)
        return np.array([0.0, 0.0, 1.0])
    if "axis" in item or "axis2" in item:  # spherical: an optional frame
        for key in ("axis", "axis2"):
            if key not in item:
                raise rd.fail(
                    f"{where}.{key}",
                    "a spherical joint's frame for angle outputs needs both axis "
                    "and axis2",
                )
        return rd.direction(item, "axis", where)
    return np.zeros(3)


def _second_axis(
    rd: Reader, item: dict, where: str, kind: str, axis: np.ndarray
) -> Float[np.ndarray, " 3"]:
    """``axis2`` of a universal joint (or of a spherical joint's frame),
    perpendicular to ``axis``; zero for the other joints."""
    if kind in ("universal", "spherical") and (kind == "universal" or "axis2" in item):
        if "axis2" not in item:
            raise rd.fail(
                f"{where}.axis2", "missing required field for a universal joint"
            )
        axis2 = rd.direction(item, "axis2", where)
        if abs(axis @ axis2) > ORTHOGONAL_TOL:
            raise rd.fail(
                f"{where}.axis2", "must be perpendicular to axis at the rest pose"
            )
        return axis2
    if "axis2" in item:
        raise rd.fail(
            f"{where}.axis2",
            "only universal and spherical joints have a second axis",
        )
    return np.zeros(3)


def _body_origins(
    rd: Reader, bodies: list[dict], joints: list[dict], ground: int, scale: float
) -> Float[np.ndarray, "B 3"]:
    """Each body's frame origin at rest: ``origin`` if given, else the centroid of its
    joint anchors. Every body must reach the ground through joints."""
    origins = np.zeros((len(bodies), 3))
    for b, body in enumerate(bodies):
        anchors = [j["anchor"] for j in joints if b in j["bodies"]]
        if not anchors:
            raise rd.fail(
                f"bodies[{b}]",
                f"body {body['name']!r} has no joint; every body must be connected",
            )
        origins[b] = (
            _position(rd, body, "origin", f"bodies[{b}]", scale)
            if "origin" in body
            else np.mean(anchors, axis=0)
        )
    reached = {ground}
    grew = True
    while grew:
        grew = False
        for j in joints:
            i, k = j["bodies"]
            if (i in reached) != (k in reached):
                reached |= {i, k}
                grew = True
    for b, body in enumerate(bodies):
        if b not in reached:
            raise rd.fail(
                f"bodies[{b}]",
                f"body {body['name']!r} is not connected to the ground through joints",
            )
    return origins


def _read_points(
    rd: Reader,
    data: dict,
    body_index: dict[str, int],
    joints: list[dict],
    scale: float,
) -> list[dict]:
    items = rd.entries(data, "points", required=False)
    rd.names(items, "points")
    joint_index = {j["name"]: k for k, j in enumerate(joints)}
    points = []
    for k, item in enumerate(items):
        where = f"points[{k}]"
        rd.keys(item, where, {"name", "body", "position", "joint"}, {"name", "body"})
        body = rd.lookup(body_index, item["body"], f"{where}.body", "body")
        if ("position" in item) == ("joint" in item):
            raise rd.fail(
                where,
                "give exactly one of 'position' (a rest position) or 'joint' "
                "(follow that joint's anchor)",
            )
        if "joint" in item:
            joint = rd.lookup(joint_index, item["joint"], f"{where}.joint", "joint")
            if body not in joints[joint]["bodies"]:
                raise rd.fail(
                    f"{where}.joint",
                    f"joint {item['joint']!r} does not touch body {item['body']!r}",
                )
            position = joints[joint]["anchor"]
        else:
            joint, position = -1, _position(rd, item, "position", where, scale)
        points.append(
            {"name": item["name"], "body": body, "joint": joint, "position": position}
        )
    return points


def _read_motors(rd: Reader, data: dict, joints: list[dict]) -> list[dict]:
    items = rd.entries(data, "motors", required=True)
    rd.names(items, "motors")
    joint_index = {j["name"]: k for k, j in enumerate(joints)}
    motors, used = [], {}
    for k, item in enumerate(items):
        where = f"motors[{k}]"
        rd.keys(item, where, {"name", "joint"}, {"name", "joint"})
        joint = rd.lookup(joint_index, item["joint"], f"{where}.joint", "joint")
        kind = joints[joint]["type"]
        if kind not in MOTOR_JOINTS:
            raise rd.fail(
                f"{where}.joint",
                f"joint {item['joint']!r} is {kind}; a motor drives a "
                f"{' or '.join(MOTOR_JOINTS)} joint",
            )
        if joint in used:
            raise rd.fail(
                f"{where}.joint",
                f"joint {item['joint']!r} already driven by motors[{used[joint]}]",
            )
        used[joint] = k
        motors.append(
            {"name": item["name"], "joint": joint, "linear": MOTOR_JOINTS[kind]}
        )
    return motors


def _read_outputs(
    rd: Reader, data: dict, points: list[dict], joints: list[dict], scale: float
) -> tuple[list[dict], list[dict]]:
    """The BK outputs and the reported ones (``reported = true``), each in file
    order; BK and the evaluation settings see the BK outputs only."""
    items = rd.entries(data, "outputs", required=True)
    rd.names(items, "outputs")
    names = {
        "point": {p["name"]: k for k, p in enumerate(points)},
        "joint": {j["name"]: k for k, j in enumerate(joints)},
        "body": {b["name"]: k for k, b in enumerate(data["bodies"])},
    }
    ground = names["body"][data["mechanism"]["ground"]]
    every = [
        _read_output(rd, item, f"outputs[{k}]", names, joints, ground, scale)
        for k, item in enumerate(items)
    ]
    outputs = [o for o in every if not o["reported"]]
    if not outputs:
        raise rd.fail(
            "[[outputs]]",
            "every output is reported; BK needs outputs without 'reported = true'",
        )
    return outputs, [o for o in every if o["reported"]]


#: Fields of an ``[[outputs]]`` entry.
OUTPUT_FIELDS = {
    "name",
    "kind",
    "point",
    "coordinate",
    "joint",
    "angle",
    "body",
    "relative_to",
    "axis",
    "axis2",
    "reported",
    "min",
    "max",
}


def _read_output(
    rd: Reader,
    item: dict,
    where: str,
    names: dict[str, dict[str, int]],
    joints: list[dict],
    ground: int,
    scale: float,
) -> dict:
    """One output: a point's Cartesian coordinate, a joint angle, a body's
    orientation angle or a joint's displacement, with its range (optional for a
    reported output)."""
    rd.keys(item, where, OUTPUT_FIELDS, {"name"})
    reported = rd.boolean(item, "reported", where) if "reported" in item else False
    entry = {
        "name": item["name"],
        "reported": reported,
        "point": -1,
        "coord": -1,
        "joint": -1,
        "bodies": (-1, -1),
        "frame": np.zeros((2, 3)),
    }
    kind = _output_kind(rd, item, where, names["joint"], joints)
    if kind == "position":
        entry.update(_point_output(rd, item, where, names["point"]))
    elif kind == "orientation":
        entry.update(_orientation_output(rd, item, where, names["body"], ground))
    else:
        entry.update(_angle_output(rd, item, where, names["joint"], joints, kind))
    entry.update(_output_range(rd, item, where, entry["kind"], reported, scale))
    return entry


def _output_kind(
    rd: Reader, item: dict, where: str, joint_index: dict[str, int], joints: list[dict]
) -> str:
    """``kind`` if given, else "position" for a ``point``, "angle" for a ``joint``
    ("displacement" if it is prismatic)."""
    if "kind" in item:
        kind = item["kind"]
        if kind not in OUTPUT_KINDS:
            raise rd.fail(
                f"{where}.kind",
                f"unknown output kind {shown(kind)}; expected one of "
                f"{list(OUTPUT_KINDS)}",
            )
    elif "point" in item and "joint" not in item:
        kind = "position"
    elif "joint" in item and "point" not in item:
        joint = rd.lookup(joint_index, item["joint"], f"{where}.joint", "joint")
        kind = "displacement" if joints[joint]["type"] == "prismatic" else "angle"
    else:
        raise rd.fail(
            where,
            "give either 'point' and 'coordinate' (a Cartesian output), 'joint' (an "
            "angle or displacement output) or kind = \"orientation\" and 'body'",
        )
    allowed = {
        "position": {"point", "coordinate"},
        "angle": {"joint", "angle"},
        "displacement": {"joint"},
        "orientation": {"body", "relative_to", "angle", "axis", "axis2"},
    }[kind] | {"name", "kind", "reported", "min", "max"}
    extra = sorted(set(item) - allowed)
    if extra:
        raise rd.fail(
            f"{where}.{field_name(extra[0])}",
            f"unknown field; expected one of {sorted(allowed)} (a {kind} output)",
        )
    needs = {"position": "point", "angle": "joint", "displacement": "joint"}
    needs["orientation"] = "body"
    if needs[kind] not in item:
        raise rd.fail(
            f"{where}.{needs[kind]}", f"missing required field for a {kind} output"
        )
    return kind


def _output_range(
    rd: Reader, item: dict, where: str, kind: str, reported: bool, scale: float
) -> dict:
    """``min < max`` (file units, rad), required unless the output is reported."""
    if reported and "min" not in item and "max" not in item:
        return {"min": float("nan"), "max": float("nan")}
    for key in ("min", "max"):
        if key not in item:
            raise rd.fail(f"{where}.{key}", "missing required field")
    low, high = rd.number(item, "min", where), rd.number(item, "max", where)
    if low >= high:
        raise rd.fail(
            f"{where}.min",
            f"target range needs min < max, got min={low} and max={high}",
        )
    _check_value(rd, f"{where}.min", [low, high], kind, scale)
    return {"min": low, "max": high}


def _check_value(rd: Reader, where: str, values, kind: str, scale: float) -> None:
    """Values of an output (a length or an angle, :data:`OUTPUT_KINDS`) within its
    bound."""
    if OUTPUT_KINDS[kind]:
        _check_position(rd, where, values, scale)
    elif float(np.max(np.abs(values))) > MAX_ANGLE:
        raise rd.fail(
            where,
            f"expected angles of magnitude at most {MAX_ANGLE:g} rad, got "
            f"{float(np.max(np.abs(values))):g}",
        )


#: Names of the orientation angles, in the order of :func:`~.joints.tait_bryan`.
ORIENTATION_ANGLES = ("roll", "pitch", "yaw")


def _orientation_output(
    rd: Reader, item: dict, where: str, body_index: dict[str, int], ground: int
) -> dict:
    """A Tait–Bryan angle of ``body`` relative to ``relative_to`` (default the
    ground): ``R_refᵀ R_body = Rot(e1, roll) Rot(e2, pitch) Rot(e1 × e2, yaw)`` with
    the frame ``e1 = axis``, ``e2 = axis2`` (default x and y, so x-y'-z''), the
    convention of a spherical joint's angle outputs."""
    body = rd.lookup(body_index, item["body"], f"{where}.body", "body")
    reference = ground
    if "relative_to" in item:
        reference = rd.lookup(
            body_index, item["relative_to"], f"{where}.relative_to", "body"
        )
    if reference == body:
        raise rd.fail(
            f"{where}.relative_to",
            f"the orientation of {item['body']!r} relative to itself is always zero",
        )
    if "angle" not in item:
        raise rd.fail(
            f"{where}.angle",
            f"missing required field for an orientation: one of "
            f"{list(ORIENTATION_ANGLES)} (or 1, 2, 3)",
        )
    return {
        "kind": "orientation",
        "bodies": (reference, body),
        "frame": _orientation_frame(rd, item, where),
        "coord": _orientation_index(rd, item, where),
    }


def _orientation_index(rd: Reader, item: dict, where: str) -> int:
    """0, 1, 2 for ``angle`` = "roll"/1, "pitch"/2, "yaw"/3."""
    value = item["angle"]
    if isinstance(value, str):
        if value not in ORIENTATION_ANGLES:
            raise rd.fail(
                f"{where}.angle",
                f"expected one of {list(ORIENTATION_ANGLES)} or 1, 2, 3, got "
                f"{shown(value)}",
            )
        return ORIENTATION_ANGLES.index(value)
    return rd.integer(item, "angle", where, 1, 3) - 1


def _orientation_frame(rd: Reader, item: dict, where: str) -> np.ndarray:
    """``(e1, e2)``: ``axis`` and ``axis2`` (both or neither, perpendicular), by
    default the world x and y axes."""
    if "axis" not in item and "axis2" not in item:
        return np.eye(3)[:2]
    for key in ("axis", "axis2"):
        if key not in item:
            raise rd.fail(
                f"{where}.{key}", "an orientation's frame needs both axis and axis2"
            )
    e1, e2 = rd.direction(item, "axis", where), rd.direction(item, "axis2", where)
    if abs(e1 @ e2) > ORTHOGONAL_TOL:
        raise rd.fail(f"{where}.axis2", "must be perpendicular to axis")
    return np.stack([e1, e2])


def _point_output(
    rd: Reader, item: dict, where: str, point_index: dict[str, int]
) -> dict:
    if "coordinate" not in item:
        raise rd.fail(
            f"{where}.coordinate",
            "missing required field for a point output (x, y or z)",
        )
    if item["coordinate"] not in ("x", "y", "z"):
        raise rd.fail(
            f"{where}.coordinate",
            f"expected 'x', 'y' or 'z', got {shown(item['coordinate'])}",
        )
    return {
        "kind": "position",
        "point": rd.lookup(point_index, item["point"], f"{where}.point", "point"),
        "coord": "xyz".index(item["coordinate"]),
    }


def _angle_output(
    rd: Reader,
    item: dict,
    where: str,
    joint_index: dict[str, int],
    joints: list[dict],
    kind: str = "angle",
) -> dict:
    """An angle of a joint or (``kind`` "displacement") the slide of a prismatic or
    cylindrical joint along its axis, zero at rest (file units)."""
    joint = rd.lookup(joint_index, item["joint"], f"{where}.joint", "joint")
    if kind == "displacement":
        if joints[joint]["type"] not in ("prismatic", "cylindrical"):
            raise rd.fail(
                f"{where}.joint",
                "a displacement output needs a prismatic or cylindrical joint, "
                f"{joints[joint]['name']!r} is {joints[joint]['type']}",
            )
        return {"kind": "displacement", "joint": joint, "coord": -1}
    return {
        "kind": "angle",
        "joint": joint,
        "coord": _angle_index(rd, item, where, joints[joint]),
    }


def _angle_index(rd: Reader, item: dict, where: str, joint: dict) -> int:
    """-1 for the angle of a revolute/cylindrical joint; ``angle - 1`` (0, 1 or 2) for
    the Tait–Bryan angles of a universal or spherical joint about its axis, axis2 and
    axis × axis2, in that intrinsic order."""
    kind, name = joint["type"], joint["name"]
    if kind in ("revolute", "cylindrical"):
        if "angle" in item:
            raise rd.fail(
                f"{where}.angle",
                f"{name!r} is {kind}: it has one angle, so give no 'angle'",
            )
        return -1
    if kind not in ("universal", "spherical"):
        raise rd.fail(
            f"{where}.joint",
            "an angle output needs a revolute, cylindrical, universal or spherical "
            f"joint, {name!r} is {kind}"
            + (" (its travel is kind = 'displacement')" if kind == "prismatic" else ""),
        )
    if kind == "spherical" and not np.any(joint["axis2"]):
        raise rd.fail(
            f"{where}.joint",
            f"spherical joint {name!r} needs axis and axis2 (the frame its angles "
            "are measured in) for an angle output",
        )
    count = 2 if kind == "universal" else 3
    if "angle" not in item:
        raise rd.fail(
            f"{where}.angle",
            f"missing required field for an angle of a {kind} joint: 1 (about axis), "
            "2 (about axis2)" + (", 3 (about axis x axis2)" if count == 3 else ""),
        )
    return rd.integer(item, "angle", where, 1, count) - 1


def diameter(points: Float[np.ndarray, "N 3"]) -> float:
    """Largest distance between two of ``points (N, 3)``: the default reference length
    (over the joint anchors) and the one the arm builders give for their bodies."""
    points = np.asarray(points, dtype=float)
    return float(np.max(np.linalg.norm(points[:, None] - points[None], axis=-1)))


def _reference_length(rd: Reader, head: dict, anchors: np.ndarray) -> float:
    span = diameter(anchors)
    if "reference_length" in head:
        return _given_reference_length(rd, head, span)
    if span <= 0:
        raise rd.fail(
            "[mechanism].reference_length",
            "all joint anchors coincide; give a positive reference_length",
        )
    if span < REFERENCE_LENGTHS[0]:
        raise rd.fail(
            "[mechanism].reference_length",
            f"the joint anchors span only {span:g} file units, below "
            f"{REFERENCE_LENGTHS[0]:g}; give a reference_length",
        )
    return span


def _given_reference_length(rd: Reader, head: dict, span: float) -> float:
    """``reference_length`` in :data:`REFERENCE_LENGTHS`, within a factor
    :data:`SCALE_RATIO` of the anchors' ``span`` (unless they all coincide)."""
    scale = rd.bounded(head, "reference_length", "[mechanism]", *REFERENCE_LENGTHS)
    if span > 0 and not span / SCALE_RATIO <= scale <= span * SCALE_RATIO:
        raise rd.fail(
            "[mechanism].reference_length",
            f"{scale:g} is not within a factor {SCALE_RATIO:g} of the span of the "
            f"joint anchors ({span:g}); lengths divided by it would be too large or "
            "too small for the solver",
        )
    return scale


def _setting(rd: Reader, table: dict, key: str, where: str, default):
    """One ``[solver]``/``[evaluation]`` value of the type of its ``default``, in
    :data:`SETTING_RANGES`."""
    if isinstance(default, bool):
        return rd.boolean(table, key, where)
    low, high = SETTING_RANGES[key]
    if isinstance(default, int):
        return rd.integer(table, key, where, int(low), int(high))
    return rd.bounded(table, key, where, low, high)


def _known(defaults) -> set[str]:
    """The fields of a settings table this loader reads: flags, ``targets`` and the
    numbers it has a range for."""
    return {
        key
        for key in defaults.__dataclass_fields__
        if key in SETTING_RANGES
        or key == "targets"
        or isinstance(getattr(defaults, key), bool)
    }


def _read_solver(rd: Reader, data: dict) -> SolverSettings:
    defaults = SolverSettings()
    if "solver" not in data:
        return defaults
    table = rd.table(data["solver"], "[solver]", _known(defaults), set())
    values = {
        key: _setting(rd, table, key, "[solver]", getattr(defaults, key))
        for key in table
    }
    return SolverSettings(**values)


def _read_evaluation(
    rd: Reader, data: dict, outputs: list[dict], scale: float
) -> EvaluationSettings:
    defaults = EvaluationSettings()
    if "evaluation" not in data:
        return defaults
    table = rd.table(data["evaluation"], "[evaluation]", _known(defaults), set())
    values = {
        key: _setting(rd, table, key, "[evaluation]", getattr(defaults, key))
        for key in table
        if key != "targets"
    }
    if "targets" in table:
        values["targets"] = _read_targets(rd, table["targets"], outputs, scale)
    settings = EvaluationSettings(**values)
    grid = settings.samples_per_dimension ** len(outputs)
    if grid + len(settings.targets) > MAX_TARGETS:
        raise rd.fail(
            "[evaluation].samples_per_dimension",
            f"{settings.samples_per_dimension} per output for {len(outputs)} outputs "
            f"makes {grid} targets; expected at most {MAX_TARGETS} in all",
        )
    return settings


def _read_targets(
    rd: Reader, value, outputs: list[dict], scale: float
) -> tuple[tuple[float, ...], ...]:
    """``[evaluation].targets``: lists of one value per output (file units), each
    inside the outputs' ranges (the adversarial samples search the range)."""
    where = "[evaluation].targets"
    if not isinstance(value, list) or len(value) > MAX_TARGETS:
        raise rd.fail(
            where,
            f"expected a list of at most {MAX_TARGETS} targets, got {shown(value)}",
        )
    targets = []
    for k, target in enumerate(value):
        if not is_number_list(target, len(outputs)):
            raise rd.fail(
                f"{where}[{k}]",
                f"expected a list of {len(outputs)} finite numbers (one per output), "
                f"got {shown(target)}",
            )
        for output, v in zip(outputs, target):
            _check_value(rd, f"{where}[{k}]", [v], output["kind"], scale)
            if not output["min"] <= v <= output["max"]:
                raise rd.fail(
                    f"{where}[{k}]",
                    f"expected a target inside the output range: {output['name']} "
                    f"in [{output['min']:g}, {output['max']:g}], got {v:g}",
                )
        targets.append(tuple(float(v) for v in target))
    return tuple(targets)
