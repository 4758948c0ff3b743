"""Mechanism definition files (TOML): parsing and validation, before any solving.

Every problem is reported as one :class:`MechanismFileError` naming the file, the
table/field and what was expected (through the shared :class:`~.fields.Reader`).
Nothing missing is silently replaced by a default; the only optional fields are those
documented in the README with their defaults (``reference_length``, ``[solver]``,
``axis`` of a fixed joint, ``[symmetry]``, ``[[parameters]]``, ``mirror``).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from jaxtyping import Float

from .fields import Reader, parse_text, parse_toml
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
    origins = _body_origins(rd, bodies, joints, ground)
    points = _read_points(rd, data, body_index, joints)
    motors = _read_motors(rd, data, joints)
    outputs = _read_outputs(rd, data, points, joints)
    anchors = np.array([j["anchor"] for j in joints])
    scale = _reference_length(rd, head, anchors)
    symmetry = _read_symmetry(rd, data)
    design = _read_design(rd, data, joints, symmetry, scale)
    solver = _read_solver(rd, data)
    evaluation = _read_evaluation(rd, data)
    mech = Mechanism(
        name=rd.string(head, "name", "[mechanism]"),
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
    if "mechanism" not in data or not isinstance(data["mechanism"], dict):
        raise rd.fail("[mechanism]", "missing table")
    return rd.keys(
        data["mechanism"],
        "[mechanism]",
        {"name", "ground", "reference_length", "units"},
        {"name", "ground"},
    )


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
            f"expected a joint type string, one of {list(JOINT_ROWS)}, got {kind!r}",
        )
    if kind not in JOINT_ROWS:
        raise rd.fail(
            f"{where}.type",
            f"unknown joint type {kind!r}; expected one of {list(JOINT_ROWS)}",
        )
    pair = _joint_bodies(rd, item, where, body_index)
    axis = _first_axis(rd, item, where, kind)
    axis2 = _second_axis(rd, item, where, kind, axis)
    return {
        "name": item["name"],
        "type": kind,
        "bodies": pair,
        "anchor": rd.vector(item, "anchor", where),
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
            f"{where}.bodies", f"expected a list of two body names, got {pair!r}"
        )
    bi = rd.lookup(body_index, pair[0], f"{where}.bodies", "body")
    bj = rd.lookup(body_index, pair[1], f"{where}.bodies", "body")
    if bi == bj:
        raise rd.fail(
            f"{where}.bodies",
            f"a joint must connect two different bodies, got {pair!r}",
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
    rd: Reader, bodies: list[dict], joints: list[dict], ground: int
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
            rd.vector(body, "origin", f"bodies[{b}]")
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
    rd: Reader, data: dict, body_index: dict[str, int], joints: list[dict]
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
            joint, position = -1, rd.vector(item, "position", where)
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
    rd: Reader, data: dict, points: list[dict], joints: list[dict]
) -> list[dict]:
    items = rd.entries(data, "outputs", required=True)
    rd.names(items, "outputs")
    point_index = {p["name"]: k for k, p in enumerate(points)}
    joint_index = {j["name"]: k for k, j in enumerate(joints)}
    return [
        _read_output(rd, item, f"outputs[{k}]", point_index, joint_index, joints)
        for k, item in enumerate(items)
    ]


def _read_output(
    rd: Reader,
    item: dict,
    where: str,
    point_index: dict[str, int],
    joint_index: dict[str, int],
    joints: list[dict],
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
    return entry


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
            f"expected 'x', 'y' or 'z', got {item['coordinate']!r}",
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
    value = item["angle"]
    if isinstance(value, bool) or value not in range(1, count + 1):
        raise rd.fail(
            f"{where}.angle", f"expected an integer from 1 to {count}, got {value!r}"
        )
    return int(value) - 1


def diameter(points: Float[np.ndarray, "N 3"]) -> float:
    """Largest distance between two of ``points (N, 3)``: the default reference length
    (over the joint anchors) and the one the arm builders give for their bodies."""
    points = np.asarray(points, dtype=float)
    return float(np.max(np.linalg.norm(points[:, None] - points[None], axis=-1)))


def _reference_length(rd: Reader, head: dict, anchors: np.ndarray) -> float:
    if "reference_length" in head:
        return rd.positive(head, "reference_length", "[mechanism]")
    span = diameter(anchors)
    if span <= 0:
        raise rd.fail(
            "[mechanism].reference_length",
            "all joint anchors coincide; give a positive reference_length",
        )
    return span


def _read_symmetry(rd: Reader, data: dict):
    if "symmetry" not in data:
        return None
    table = rd.keys(
        data["symmetry"], "[symmetry]", {"normal", "point"}, {"normal", "point"}
    )
    return rd.direction(table, "normal", "[symmetry]"), rd.vector(
        table, "point", "[symmetry]"
    )


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
            f"expected one of {list(COORDINATES)}, got {coord!r}",
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
            f"{item['joint']!r}: only revolute, universal, prismatic and cylindrical "
            "joints have a movable axis",
        )
    value = (joints[joint]["axis"] if is_axis else joints[joint]["anchor"])[c]
    low, high = _parameter_bounds(rd, item, where, value, joints[joint]["name"])
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
            f"the rest value {value:g} of {joint_name}.{item['coordinate']} lies "
            f"outside [{low:g}, {high:g}]",
        )
    return low, high


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


def _read_solver(rd: Reader, data: dict) -> SolverSettings:
    defaults = SolverSettings()
    if "solver" not in data:
        return defaults
    table = rd.keys(
        data["solver"],
        "[solver]",
        {"max_iterations", "tolerance", "initial_damping"},
        set(),
    )
    iterations = table.get("max_iterations", defaults.max_iterations)
    if (
        isinstance(iterations, bool)
        or not isinstance(iterations, int)
        or iterations < 1
    ):
        raise rd.fail(
            "[solver].max_iterations",
            f"expected a positive integer, got {iterations!r}",
        )
    tolerance = (
        rd.positive(table, "tolerance", "[solver]")
        if "tolerance" in table
        else defaults.tolerance
    )
    damping = (
        rd.positive(table, "initial_damping", "[solver]")
        if "initial_damping" in table
        else defaults.initial_damping
    )
    return SolverSettings(
        max_iterations=iterations, tolerance=tolerance, initial_damping=damping
    )


def _read_evaluation(rd: Reader, data: dict) -> EvaluationSettings:
    defaults = EvaluationSettings()
    if "evaluation" not in data:
        return defaults
    fields = set(EvaluationSettings.__dataclass_fields__)
    table = rd.keys(data["evaluation"], "[evaluation]", fields, set())
    values = {}
    for key, _ in table.items():
        default = getattr(defaults, key)
        if isinstance(default, bool):
            values[key] = rd.boolean(table, key, "[evaluation]")
        elif isinstance(default, int):
            values[key] = rd.positive_integer(table, key, "[evaluation]")
        else:  # a float, or None: an optional positive number
            values[key] = rd.positive(table, key, "[evaluation]")
    settings = EvaluationSettings(**values)
    if settings.samples_per_dimension < 2:
        raise rd.fail(
            "[evaluation].samples_per_dimension",
            "expected at least 2 (the range's two ends)",
        )
    return settings
