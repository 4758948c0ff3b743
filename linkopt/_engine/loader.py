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

from pathlib import Path

import numpy as np
from jaxtyping import Float

from .fields import (
    Reader,
    field_name,
    is_number_list,
    parse_text,
    parse_toml,
    shown,
)
from .model import (
    AXIAL_JOINTS,
    COORDINATES,
    JOINT_ROWS,
    MOTOR_JOINTS,
    DesignSpace,
    EvaluationSettings,
    Mechanism,
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
}
ORTHOGONAL_TOL = 1e-9
MIRROR_TOL = 1e-9
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
    rd = Reader(source)
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
    outputs = _read_outputs(rd, data, points, joints, scale)
    symmetry = _read_symmetry(rd, data, scale)
    design = _read_design(rd, data, joints, symmetry, scale)
    solver = _read_solver(rd, data)
    evaluation = _read_evaluation(rd, data, outputs, scale)
    mech = Mechanism(
        name=head["name"],
        source=source,
        **_body_fields(bodies, ground, origins),
        **_joint_fields(joints, anchors),
        **_point_fields(points),
        **_motor_fields(motors),
        **_output_fields(outputs),
        design=design,
        length_scale=scale,
        solver=solver,
        evaluation=evaluation,
        symmetry=symmetry,
        raw=data,
    )
    if check:
        from .mobility import check_mobility  # needs JAX; kept out of pure parsing

        check_mobility(mech)
    return mech


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
        rd.keys(body, f"bodies[{k}]", {"name", "origin"}, {"name"})
    return bodies, body_index


def _body_fields(bodies: list[dict], ground: int, origins: np.ndarray) -> dict:
    return {
        "body_names": tuple(b["name"] for b in bodies),
        "ground": ground,
        "body_origins": origins,
    }


def _joint_fields(joints: list[dict], anchors: np.ndarray) -> dict:
    pairs = np.array([j["bodies"] for j in joints], dtype=int).reshape(-1, 2)
    return {
        "joint_names": tuple(j["name"] for j in joints),
        "joint_types": tuple(j["type"] for j in joints),
        "joint_bodies": pairs,
        "anchors": anchors,
        "axes": np.array([j["axis"] for j in joints]),
        "axes2": np.array([j["axis2"] for j in joints]),
    }


def _point_fields(points: list[dict]) -> dict:
    positions = np.array([p["position"] for p in points]).reshape(-1, 3)
    return {
        "point_names": tuple(p["name"] for p in points),
        "point_bodies": np.array([p["body"] for p in points], dtype=int),
        "point_joints": np.array([p["joint"] for p in points], dtype=int),
        "point_positions": positions,
    }


def _motor_fields(motors: list[dict]) -> dict:
    return {
        "motor_names": tuple(m["name"] for m in motors),
        "motor_joints": np.array([m["joint"] for m in motors], dtype=int),
        "motor_linear": np.array([m["linear"] for m in motors], dtype=bool),
    }


def _output_fields(outputs: list[dict]) -> dict:
    return {
        "output_names": tuple(o["name"] for o in outputs),
        "output_kinds": tuple(o["kind"] for o in outputs),
        "output_points": np.array([o["point"] for o in outputs], dtype=int),
        "output_coords": np.array([o["coord"] for o in outputs], dtype=int),
        "output_joints": np.array([o["joint"] for o in outputs], dtype=int),
        "output_min": np.array([o["min"] for o in outputs], dtype=float),
        "output_max": np.array([o["max"] for o in outputs], dtype=float),
    }


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
) -> list[dict]:
    items = rd.entries(data, "outputs", required=True)
    rd.names(items, "outputs")
    point_index = {p["name"]: k for k, p in enumerate(points)}
    joint_index = {j["name"]: k for k, j in enumerate(joints)}
    return [
        _read_output(rd, item, f"outputs[{k}]", point_index, joint_index, joints, scale)
        for k, item in enumerate(items)
    ]


def _read_output(
    rd: Reader,
    item: dict,
    where: str,
    point_index: dict[str, int],
    joint_index: dict[str, int],
    joints: list[dict],
    scale: float,
) -> dict:
    """One output: a point's Cartesian coordinate or a joint angle, with its range."""
    rd.keys(
        item,
        where,
        {"name", "point", "coordinate", "joint", "angle", "min", "max"},
        {"name", "min", "max"},
    )
    low, high = rd.number(item, "min", where), rd.number(item, "max", where)
    if low >= high:
        raise rd.fail(
            f"{where}.min",
            f"target range needs min < max, got min={low} and max={high}",
        )
    entry = {
        "name": item["name"],
        "min": low,
        "max": high,
        "point": -1,
        "coord": -1,
        "joint": -1,
    }
    if "point" in item and "joint" not in item:
        entry.update(_point_output(rd, item, where, point_index))
    elif "joint" in item and "point" not in item:
        entry.update(_angle_output(rd, item, where, joint_index, joints))
    else:
        raise rd.fail(
            where,
            "give either 'point' and 'coordinate' (a Cartesian output) or 'joint' "
            "(an angle output)",
        )
    _check_value(rd, f"{where}.min", [low, high], entry["kind"], scale)
    return entry


def _check_value(rd: Reader, where: str, values, kind: str, scale: float) -> None:
    """Values of an output (``kind`` "position" or "angle") within its bound."""
    if kind == "position":
        _check_position(rd, where, values, scale)
    elif float(np.max(np.abs(values))) > MAX_ANGLE:
        raise rd.fail(
            where,
            f"expected angles of magnitude at most {MAX_ANGLE:g} rad, got "
            f"{float(np.max(np.abs(values))):g}",
        )


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
) -> dict:
    if "coordinate" in item:
        raise rd.fail(f"{where}.coordinate", "an angle output has no coordinate")
    joint = rd.lookup(joint_index, item["joint"], f"{where}.joint", "joint")
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
            f"joint, {name!r} is {kind}",
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


def _read_symmetry(rd: Reader, data: dict, scale: float):
    if "symmetry" not in data:
        return None
    table = rd.table(
        data["symmetry"], "[symmetry]", {"normal", "point"}, {"normal", "point"}
    )
    normal = rd.direction(table, "normal", "[symmetry]")
    return normal, _position(rd, table, "point", "[symmetry]", scale)


def _reflect(point: np.ndarray, symmetry) -> np.ndarray:
    normal, origin = symmetry
    return point - 2.0 * ((point - origin) @ normal) * normal


def _joint_group(
    rd: Reader,
    value,
    where: str,
    joint_index: dict[str, int],
    joints: list[dict],
    is_axis: bool,
    scale: float,
) -> list[int]:
    """A joint name, or a list of joints that coincide at rest and move as one."""
    names = value if isinstance(value, list) and value else [value]
    group = [rd.lookup(joint_index, name, where, "joint") for name in names]
    key = "axis" if is_axis else "anchor"
    tolerance = MIRROR_TOL if is_axis else MIRROR_TOL * scale
    for name, index in zip(names[1:], group[1:]):
        if np.linalg.norm(joints[index][key] - joints[group[0]][key]) > tolerance:
            raise rd.fail(
                where,
                f"joints moved together must share their {key} at rest; {name!r} "
                f"differs from {names[0]!r}",
            )
    if len(set(group)) != len(group):
        raise rd.fail(where, "a joint is listed twice")
    return group


def _read_design(
    rd: Reader, data: dict, joints: list[dict], symmetry, scale: float
) -> DesignSpace:
    """Free parameters; each drives one coordinate of a joint (or of coincident
    joints)."""
    items = rd.entries(data, "parameters", required=False)
    rd.names(items, "parameters")
    joint_index = {j["name"]: k for k, j in enumerate(joints)}
    matrix = np.zeros((6 * len(joints), len(items)))
    p0, lower, upper, owner = [], [], [], {}
    for k, item in enumerate(items):
        where = f"parameters[{k}]"
        value, low, high, driven = _read_parameter(
            rd, item, where, joint_index, joints, symmetry, scale
        )
        _claim_rows(rd, where, k, driven, owner, matrix)
        p0.append(value)
        lower.append(low)
        upper.append(high)
    is_length = np.array(
        [not str(i["coordinate"]).startswith("axis_") for i in items], dtype=bool
    )
    return DesignSpace(
        tuple(i["name"] for i in items),
        np.array(p0, dtype=float),
        np.array(lower, dtype=float),
        np.array(upper, dtype=float),
        matrix,
        is_length,
    )


def _read_parameter(
    rd: Reader,
    item: dict,
    where: str,
    joint_index: dict[str, int],
    joints: list[dict],
    symmetry,
    scale: float,
) -> tuple[float, float, float, list[tuple[int, float]]]:
    """One parameter: its rest value, bounds and the (row, weight) pairs of the flat
    geometry it drives, mirror twins included."""
    rd.keys(
        item,
        where,
        {"name", "joint", "coordinate", "min", "max", "mirror"},
        {"name", "joint", "coordinate", "min", "max"},
    )
    coord = item["coordinate"]
    if coord not in COORDINATES:
        raise rd.fail(
            f"{where}.coordinate",
            f"expected one of {list(COORDINATES)}, got {shown(coord)}",
        )
    is_axis = coord.startswith("axis_")
    c = "xyz".index(coord[-1])
    group = _joint_group(
        rd, item["joint"], f"{where}.joint", joint_index, joints, is_axis, scale
    )
    joint = group[0]
    if is_axis and any(joints[g]["type"] not in AXIAL_JOINTS for g in group):
        raise rd.fail(
            f"{where}.coordinate",
            f"{shown(item['joint'])}: only revolute, universal, prismatic and "
            "cylindrical joints have a movable axis",
        )
    value = (joints[joint]["axis"] if is_axis else joints[joint]["anchor"])[c]
    low, high = _parameter_bounds(rd, item, where, value, joints[joint]["name"])
    _check_bound_magnitude(rd, f"{where}.min", (low, high), is_axis, scale)
    base = 3 * len(joints) if is_axis else 0
    driven = [(base + 3 * g + c, 1.0) for g in group]
    if "mirror" in item:
        mirrors = _joint_group(
            rd, item["mirror"], f"{where}.mirror", joint_index, joints, is_axis, scale
        )
        for mirror in mirrors:
            driven += _mirror_rows(
                rd, where, joints, joint, mirror, c, is_axis, symmetry, scale, group
            )
    return value, low, high, driven


def _parameter_bounds(
    rd: Reader, item: dict, where: str, value: float, joint_name: str
) -> tuple[float, float]:
    """``min < max``, with the rest value between them."""
    low, high = rd.number(item, "min", where), rd.number(item, "max", where)
    if not low < high:
        raise rd.fail(
            f"{where}.min", f"bounds need min < max, got min={low} and max={high}"
        )
    if not low <= value <= high:
        raise rd.fail(
            f"{where}.min",
            f"the rest value {value:g} of {field_name(joint_name)}."
            f"{item['coordinate']} lies outside [{low:g}, {high:g}]",
        )
    return low, high


def _check_bound_magnitude(
    rd: Reader, where: str, bounds: tuple[float, float], is_axis: bool, scale: float
) -> None:
    """Anchor-parameter bounds are positions; axis-component ones at most
    :data:`MAX_EXTENT`."""
    if not is_axis:
        _check_position(rd, where, bounds, scale)
    elif max(abs(b) for b in bounds) > MAX_EXTENT:
        raise rd.fail(
            where,
            f"expected axis-component bounds of magnitude at most {MAX_EXTENT:g}, "
            f"got min={bounds[0]:g} and max={bounds[1]:g}",
        )


def _claim_rows(
    rd: Reader,
    where: str,
    k: int,
    driven: list[tuple[int, float]],
    owner: dict[int, int],
    matrix: Float[np.ndarray, "rows n_p"],
) -> None:
    """Parameter ``k`` takes the rows it drives; no row has two parameters."""
    for row, _ in driven:
        if row in owner:
            raise rd.fail(
                where,
                f"drives a coordinate already driven by parameters[{owner[row]}]",
            )
    for row, weight in driven:
        owner[row] = k
        matrix[row, k] = weight


def _mirror_rows(rd, where, joints, joint, mirror, c, is_axis, symmetry, scale, group):
    """Rows and weights through which a parameter moves its mirror-image joint."""
    if symmetry is None:
        raise rd.fail(
            f"{where}.mirror",
            "a mirror tie needs a [symmetry] table (normal and point)",
        )
    if mirror in group:
        raise rd.fail(f"{where}.mirror", "a joint cannot mirror itself")
    name, twin = joints[joint]["name"], joints[mirror]["name"]
    normal = symmetry[0]
    direction = np.eye(3)[c] - 2.0 * normal[c] * normal
    if is_axis:
        image = joints[joint]["axis"] - 2.0 * (joints[joint]["axis"] @ normal) * normal
        sign = 1.0 if image @ joints[mirror]["axis"] > 0 else -1.0
        if np.linalg.norm(sign * image - joints[mirror]["axis"]) > MIRROR_TOL:
            raise rd.fail(
                f"{where}.mirror",
                f"axis of {twin!r} is not the mirror image of the axis of {name!r}",
            )
        base, weights = 3 * len(joints), sign * direction
    else:
        image = _reflect(joints[joint]["anchor"], symmetry)
        if np.linalg.norm(image - joints[mirror]["anchor"]) > MIRROR_TOL * scale:
            raise rd.fail(
                f"{where}.mirror",
                f"anchor of {twin!r} is not the mirror image of the anchor of {name!r}",
            )
        base, weights = 0, direction
    return [(base + 3 * mirror + d, weights[d]) for d in range(3) if weights[d] != 0.0]


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
