"""The bodies and joints of a mechanism file: ``[[bodies]]``, ``[[joints]]``, the
bodies' frame origins and the most bodies a file may have."""

from __future__ import annotations

import numpy as np
from jaxtyping import Float

from .._engine.model import AXIAL_JOINTS, JOINT_ROWS
from .._errors import MechanismFileError
from .bounds import ORTHOGONAL_TOL, position
from .fields import Reader, shown

#: Most bodies of a mechanism (:func:`check_size`). Where the bodies fall into a narrow
#: band (:func:`linkopt._engine.banded.serves`) the solves, the design evaluation and
#: the load-time checks (mobility, σ_min at rest: :mod:`linkopt._engine.mobility`)
#: all work on the banded factor, linear in the bodies, and what limits a file is
#: memory and time. Measured on generated ladders (2-core machine, loaded): at 1000
#: bodies ``linkopt check`` takes 62 s wall (10 s CPU, mostly compiling) and 455 MB,
#: an FK solve from rest 0.13-0.5 s, an evaluated sample 17 s and the evaluation 1.4
#: GB; at 3000 bodies loading takes 135 s and 1.4 GB and an FK solve 8 s (44 LM
#: iterations: the far end magnifies the motor's turn). About 0.5 MB per body
#: loading and 1 MB per body evaluating: 5000 bodies load in a few minutes and
#: evaluate in about 5 GB, minutes per sample; beyond that a file no longer fits a
#: sitting.
MAX_BODIES = 5000
#: Most bodies of a mechanism whose bodies fall into no narrow band
#: (:func:`check_band`): its checks and solves factor dense ``7B x 7B`` matrices
#: (an SVD at load: a 300-body ladder forced dense loaded in about 200 s and 0.9 GB).
DENSE_MAX_BODIES = 300


def check_size(rd: Reader, data: dict) -> None:
    """Refuse, before any work, a mechanism of more than :data:`MAX_BODIES` bodies."""
    bodies = data.get("bodies")
    if not isinstance(bodies, list) or len(bodies) <= MAX_BODIES:
        return
    raise rd.fail(
        "[[bodies]]",
        f"{len(bodies)} bodies make a state of {7 * len(bodies)} numbers; linkopt "
        f"takes at most {MAX_BODIES} bodies (time per solve and per evaluated sample "
        "grow with the bodies)",
    )


def check_band(mech) -> None:
    """Refuse a mechanism of more than :data:`DENSE_MAX_BODIES` bodies that the banded
    factor does not serve (:func:`linkopt._engine.banded.serves`): its load-time
    checks and solves are dense, cubic in the bodies."""
    from .._engine import banded  # needs JAX; not for parsing

    if mech.num_bodies <= DENSE_MAX_BODIES or banded.serves(mech):
        return
    size = mech.state_size
    raise MechanismFileError(
        mech.source,
        "[[bodies]]",
        f"{mech.num_bodies} bodies whose joints fall into no narrow band (no order "
        f"keeps the bodies that share a joint within 1/8 of the bodies of each "
        f"other): loading checks them on a dense {size} x {size} matrix "
        f"({8.0 * size * size / 2**20:.0f} MB, cubic time in the bodies); linkopt "
        f"takes at most {DENSE_MAX_BODIES} such bodies",
    )


def read_bodies(rd: Reader, data: dict) -> tuple[list[dict], dict[str, int]]:
    bodies = rd.entries(data, "bodies", required=True)
    body_index = rd.names(bodies, "bodies")
    for k, body in enumerate(bodies):
        rd.keys(body, f"bodies[{k}]", {"name", "origin", "radius", "layer"}, {"name"})
    return bodies, body_index


def body_fields(bodies: list[dict], ground: int, origins: np.ndarray) -> dict:
    return {
        "body_names": tuple(b["name"] for b in bodies),
        "ground": ground,
        "body_origins": origins,
    }


def joint_fields(joints: list[dict], anchors: np.ndarray) -> dict:
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


def read_joints(rd: Reader, data: dict, body_index: dict[str, int]) -> list[dict]:
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
        "anchor": position(rd, item, "anchor", where, None),
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


def body_origins(
    rd: Reader, bodies: list[dict], joints: list[dict], ground: int, scale: float
) -> Float[np.ndarray, "B 3"]:
    """Each body's frame origin at rest: ``origin`` if given, else the centroid of its
    pins' anchors (:func:`pins`). Every body must reach the ground through joints."""
    origins = np.zeros((len(bodies), 3))
    for b, body in enumerate(bodies):
        anchors = [joints[k]["anchor"] for k in pins(joints, b)]
        if not anchors:
            raise rd.fail(
                f"bodies[{b}]",
                f"body {body['name']!r} has no joint; every body must be connected",
            )
        origins[b] = (
            position(rd, body, "origin", f"bodies[{b}]", scale)
            if "origin" in body
            else np.mean(anchors, axis=0)
        )
    _check_connected(rd, bodies, joints, ground)
    return origins


def pins(joints: list[dict], body: int) -> list[int]:
    """The joints of ``body`` that place its frame and its points: all but its
    ``fixed`` joints, unless it has only those. A weld's anchor is not a pin of the
    part, so welding a part onto a body moves neither the body's origin nor its
    points' rule, and a welded part changes no number
    (:mod:`linkopt._engine.welding`)."""
    mine = [k for k, j in enumerate(joints) if body in j["bodies"]]
    own = [k for k in mine if joints[k]["type"] != "fixed"]
    return own or mine


def _check_connected(
    rd: Reader, bodies: list[dict], joints: list[dict], ground: int
) -> None:
    """Every body reaches the ground through joints."""
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
