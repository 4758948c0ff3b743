"""The outputs of a mechanism file (``[[outputs]]``): a point's Cartesian coordinate,
a joint's angle or displacement, a body's orientation angle or the tilt of a body's
axis (direction), each with its range; the BK outputs and the reported ones."""

from __future__ import annotations

import numpy as np

from .._engine.model import OUTPUT_KINDS, OutputTable
from .bounds import ORTHOGONAL_TOL, check_value
from .fields import Reader, field_name, shown


def read_outputs(
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
    elif kind == "direction":
        entry.update(_direction_output(rd, item, where, names["body"], ground))
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
            'angle or displacement output) or kind = "orientation" or '
            "\"direction\" and 'body'",
        )
    _check_kind_fields(rd, item, where, kind)
    return kind


#: The fields of each kind of output, besides those of every output.
KIND_FIELDS = {
    "position": {"point", "coordinate"},
    "angle": {"joint", "angle"},
    "displacement": {"joint"},
    "orientation": {"body", "relative_to", "angle", "axis", "axis2"},
    "direction": {"body", "relative_to", "angle", "axis", "axis2"},
}
#: The field each kind of output needs.
KIND_NEEDS = {
    "position": "point",
    "angle": "joint",
    "displacement": "joint",
    "orientation": "body",
    "direction": "body",
}


def _check_kind_fields(rd: Reader, item: dict, where: str, kind: str) -> None:
    """Only the fields of a ``kind`` output, and the one it needs."""
    allowed = KIND_FIELDS[kind] | {"name", "kind", "reported", "min", "max"}
    extra = sorted(set(item) - allowed)
    if extra:
        raise rd.fail(
            f"{where}.{field_name(extra[0])}",
            f"unknown field; expected one of {sorted(allowed)} (a {kind} output)",
        )
    if KIND_NEEDS[kind] not in item:
        raise rd.fail(
            f"{where}.{KIND_NEEDS[kind]}", f"missing required field for a {kind} output"
        )


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
    for key, value in (("min", low), ("max", high)):
        check_value(rd, f"{where}.{key}", [value], kind, scale)
    return {"min": low, "max": high}


#: Names of the orientation angles, in the order of :func:`~.joints.tait_bryan`.
ORIENTATION_ANGLES = ("roll", "pitch", "yaw")


def _orientation_output(
    rd: Reader, item: dict, where: str, body_index: dict[str, int], ground: int
) -> dict:
    """A Tait–Bryan angle of ``body`` relative to ``relative_to`` (default the
    ground): ``R_refᵀ R_body = Rot(e1, roll) Rot(e2, pitch) Rot(e1 × e2, yaw)`` with
    the frame ``e1 = axis``, ``e2 = axis2`` (default x and y, so x-y'-z''), the
    convention of a spherical joint's angle outputs."""
    bodies = _body_pair(rd, item, where, body_index, ground, "orientation")
    if "angle" not in item:
        raise rd.fail(
            f"{where}.angle",
            f"missing required field for an orientation: one of "
            f"{list(ORIENTATION_ANGLES)} (or 1, 2, 3)",
        )
    return {
        "kind": "orientation",
        "bodies": bodies,
        "frame": _orientation_frame(rd, item, where),
        "coord": _orientation_index(rd, item, where),
    }


def _body_pair(
    rd: Reader,
    item: dict,
    where: str,
    body_index: dict[str, int],
    ground: int,
    what: str,
) -> tuple[int, int]:
    """``(relative_to, body)`` of an orientation or direction output (default: the
    ground), two different bodies."""
    body = rd.lookup(body_index, item["body"], f"{where}.body", "body")
    reference = ground
    if "relative_to" in item:
        reference = rd.lookup(
            body_index, item["relative_to"], f"{where}.relative_to", "body"
        )
    if reference == body:
        raise rd.fail(
            f"{where}.relative_to",
            f"the {what} of {item['body']!r} relative to itself is always zero",
        )
    return reference, body


def _direction_output(
    rd: Reader, item: dict, where: str, body_index: dict[str, int], ground: int
) -> dict:
    """A tilt angle of ``body``'s ``axis`` relative to ``relative_to`` (default the
    ground): component ``angle`` (1: about ``axis2``, 2: about ``axis × axis2``) of
    the rotation vector of the shortest rotation taking ``axis`` to where the body
    has turned it (:func:`linkopt._engine.joints.direction_angles`)."""
    bodies = _body_pair(rd, item, where, body_index, ground, "direction")
    for key, meaning in (("axis", "the body's axis"), ("angle", "1 or 2")):
        if key not in item:
            raise rd.fail(
                f"{where}.{key}",
                f"missing required field for a direction output: {meaning}",
            )
    axis = rd.direction(item, "axis", where)
    if "axis2" in item:
        first = rd.direction(item, "axis2", where)
        if abs(axis @ first) > ORTHOGONAL_TOL:
            raise rd.fail(f"{where}.axis2", "must be perpendicular to axis")
    else:
        first = default_tilt_axis(axis)
    return {
        "kind": "direction",
        "bodies": bodies,
        "frame": np.stack([axis, first]),
        "coord": rd.integer(item, "angle", where, 1, 2) - 1,
    }


def default_tilt_axis(axis: np.ndarray) -> np.ndarray:
    """The first tilt axis of a direction output without ``axis2``: the world axis
    (x, y, z) least aligned with ``axis`` (the first on a tie), made perpendicular to
    it and unit (for ``axis`` z: x, and the second tilt axis ``z × x = y``)."""
    world = np.eye(3)[int(np.argmin(np.abs(axis)))]
    first = world - (world @ axis) * axis
    return first / np.linalg.norm(first)


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


def output_fields(outputs: list[dict], reported: list[dict] = ()) -> dict:
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
