"""Named points and motors of a mechanism file (``[[points]]``, ``[[motors]]``), and
the bodies whose spin about their own axis is idle."""

from __future__ import annotations

import numpy as np

from .._engine.attachment import attach
from .._engine.model import MOTOR_JOINTS
from .bounds import check_position, position
from .fields import Reader
from .topology import pins


def read_points(
    rd: Reader,
    data: dict,
    body_index: dict[str, int],
    joints: list[dict],
    scale: float,
) -> list[dict]:
    """``[[points]]``: each named point's body, the joint it follows (-1 for none) and
    its rest position (file units)."""
    items = rd.entries(data, "points", required=False)
    rd.names(items, "points")
    names = {"body": body_index, "joint": {j["name"]: k for k, j in enumerate(joints)}}
    return [
        _read_point(rd, item, f"points[{k}]", names, joints, scale)
        for k, item in enumerate(items)
    ]


def _read_point(
    rd: Reader,
    item: dict,
    where: str,
    names: dict[str, dict[str, int]],
    joints: list[dict],
    scale: float,
) -> dict:
    """One point: at ``position``, or following the anchor of ``joint``."""
    rd.keys(
        item, where, {"name", "body", "position", "joint", "follow"}, {"name", "body"}
    )
    body = rd.lookup(names["body"], item["body"], f"{where}.body", "body")
    if ("position" in item) == ("joint" in item):
        raise rd.fail(
            where,
            "give exactly one of 'position' (a rest position) or 'joint' "
            "(follow that joint's anchor)",
        )
    if "joint" in item:
        joint = rd.lookup(names["joint"], item["joint"], f"{where}.joint", "joint")
        if body not in joints[joint]["bodies"]:
            raise rd.fail(
                f"{where}.joint",
                f"joint {item['joint']!r} does not touch body {item['body']!r}",
            )
        rest = joints[joint]["anchor"]
    else:
        joint, rest = -1, position(rd, item, "position", where, scale)
    return {
        "name": item["name"],
        "body": body,
        "joint": joint,
        "position": rest,
        "follow": _follow_rule(rd, item, where),
    }


#: ``[[points]].follow``: how a point moves when a design moves its body's anchors.
FOLLOW_RULES = ("frame", "anchors")
#: The rule of a point given by ``position`` without ``follow``.
DEFAULT_FOLLOW = "frame"


def _follow_rule(rd: Reader, item: dict, where: str) -> str:
    """``follow``: ``"frame"`` (fixed in its body's frame, the default) or
    ``"anchors"``; a point given by ``joint`` follows that joint and takes no rule."""
    if "follow" not in item:
        return "anchors" if "joint" in item else DEFAULT_FOLLOW
    if "joint" in item:
        raise rd.fail(
            f"{where}.follow", "a point given by 'joint' follows that joint; drop it"
        )
    rule = rd.string(item, "follow", where)
    if rule not in FOLLOW_RULES:
        raise rd.fail(
            f"{where}.follow",
            f"expected one of {', '.join(map(repr, FOLLOW_RULES))}, got {rule!r}",
        )
    return rule


def read_motors(rd: Reader, data: dict, joints: list[dict], scale: float) -> list[dict]:
    """``[[motors]]``: each drives one revolute or prismatic joint, no joint twice,
    with its optional limits (:func:`_read_limits`)."""
    items = rd.entries(data, "motors", required=True)
    rd.names(items, "motors")
    joint_index = {j["name"]: k for k, j in enumerate(joints)}
    motors, used = [], {}
    for k, item in enumerate(items):
        where = f"motors[{k}]"
        rd.keys(item, where, {"name", "joint", "min", "max"}, {"name", "joint"})
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
        linear = MOTOR_JOINTS[kind]
        motors.append(
            {"name": item["name"], "joint": joint, "linear": linear}
            | _read_limits(rd, item, where, linear, scale)
        )
    return motors


#: Largest |limit| of a rotary motor (rad): motor values read off a state are angles
#: in (-π, π], so a limit past π could never be told from one on the other side.
MAX_TURN = float(np.pi)


def _read_limits(
    rd: Reader, item: dict, where: str, linear: bool, scale: float
) -> dict:
    """A motor's ``min`` and ``max`` (rad, or file units of stroke for a linear
    motor, from the rest pose like its values): each optional, a side not given is
    unlimited (``-inf`` / ``inf``). The rest value 0 must lie in ``[min, max]`` (the
    samples and the continuation start there) and ``min < max``."""
    limits = {"min": -np.inf, "max": np.inf}
    for key in ("min", "max"):
        if key not in item:
            continue
        value = rd.number(item, key, where)
        if linear:
            check_position(rd, f"{where}.{key}", value, scale)
        elif abs(value) > MAX_TURN:
            raise rd.fail(
                f"{where}.{key}",
                f"expected a rotary limit within ±π rad, got {value:g}",
            )
        limits[key] = value
    if not limits["min"] <= 0.0 <= limits["max"]:
        side = "min" if limits["min"] > 0.0 else "max"
        raise rd.fail(
            f"{where}.{side}",
            f"the rest value 0 must lie within [min, max], got {side}={limits[side]:g}",
        )
    if not limits["min"] < limits["max"]:
        raise rd.fail(
            f"{where}.min",
            f"motor limits need min < max, got min={limits['min']:g} and "
            f"max={limits['max']:g}",
        )
    return limits


def point_fields(
    points: list[dict], joints: list[dict], anchors: np.ndarray, scale: float
) -> dict:
    """The Mechanism fields of the named points, with how each follows its body."""
    positions = np.array([p["position"] for p in points]).reshape(-1, 3)
    on_body = [np.array(pins(joints, p["body"])) for p in points]
    follows = np.array([p["joint"] for p in points], dtype=int)
    fixed = np.array([p["follow"] == "frame" for p in points], dtype=bool)
    return {
        "point_names": tuple(p["name"] for p in points),
        "point_bodies": np.array([p["body"] for p in points], dtype=int),
        "point_joints": follows,
        "point_positions": positions,
        "point_attachment": attach(anchors, on_body, positions, follows, scale, fixed),
    }


def motor_fields(motors: list[dict]) -> dict:
    """The Mechanism fields of the motors; ``motor_min`` / ``motor_max`` only when a
    motor of the file has a limit (else the fields stay None, and every program is as
    without limits)."""
    lower = np.array([m["min"] for m in motors], dtype=float)
    upper = np.array([m["max"] for m in motors], dtype=float)
    limited = bool(np.isfinite(lower).any() or np.isfinite(upper).any())
    return {
        "motor_names": tuple(m["name"] for m in motors),
        "motor_joints": np.array([m["joint"] for m in motors], dtype=int),
        "motor_linear": np.array([m["linear"] for m in motors], dtype=bool),
    } | ({"motor_min": lower, "motor_max": upper} if limited else {})


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
    axis moves no other body and no output.

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
