"""``[collision]`` and the per-body ``radius`` and ``layer``, read into the static
collision model (:func:`linkopt._engine.links.build_collision`); the loader calls
:func:`read_collision` once the rest of the file is read.
"""

from __future__ import annotations

import numpy as np

from .._engine.links import (
    CLEARANCE_FRACTION,
    build_collision,
    default_pairs,
    default_thickness,
)
from .._engine.model import Collision, Mechanism
from .fields import Reader, shown

#: Default weight of the collision term in ``f_design``.
DEFAULT_WEIGHT = 1.0
#: Keys of ``[collision]``.
COLLISION_KEYS = {
    "enable",
    "thickness",
    "clearance",
    "weight",
    "normal",
    "include",
    "exclude",
}
#: Largest weight, thickness and clearance, as for the ``[evaluation]`` weights and in
#: reference lengths.
MAX_WEIGHT = 1e6
MAX_SIZE = 1.0
#: Two joint axes this close to parallel (|sin| of their angle) share a plane normal.
PARALLEL_TOL = 1e-9


def _body_sizes(rd: Reader, mech: Mechanism, thickness: float) -> tuple:
    """Per-body capsule radii and layer offsets (file units) from ``[[bodies]]``."""
    radii = np.full(mech.num_bodies, 0.5 * thickness)
    layers = np.zeros(mech.num_bodies)
    for k, body in enumerate(mech.raw.get("bodies", [])):
        where = f"bodies[{k}]"
        if "radius" in body:
            radii[k] = rd.bounded(
                body, "radius", where, 1e-9 * mech.length_scale, mech.length_scale
            )
        if "layer" in body:
            layers[k] = rd.bounded(
                body, "layer", where, -mech.length_scale, mech.length_scale
            )
    return radii, layers


def _plane_normal(rd: Reader, mech: Mechanism, table: dict) -> np.ndarray | None:
    """``[collision].normal``, else the common axis of the revolute and cylindrical
    joints when they are all parallel (a planar mechanism), else None."""
    if "normal" in table:
        return rd.direction(table, "normal", "[collision]")
    axial = [
        mech.axes[j]
        for j, kind in enumerate(mech.joint_types)
        if kind in ("revolute", "cylindrical")
    ]
    if not axial:
        return None
    first = axial[0]
    if all(np.linalg.norm(np.cross(first, a)) <= PARALLEL_TOL for a in axial):
        return np.asarray(first, dtype=float)
    return None


def _pair_list(rd: Reader, table: dict, key: str, mech: Mechanism) -> set:
    """``include``/``exclude``: a list of ``[body, body]`` pairs of distinct bodies."""
    where = f"[collision].{key}"
    value = table.get(key, [])
    if not isinstance(value, list):
        raise rd.fail(
            where, f"expected a list of [body, body] pairs, got {shown(value)}"
        )
    index = {name: b for b, name in enumerate(mech.body_names)}
    pairs = set()
    for k, pair in enumerate(value):
        if not isinstance(pair, list) or len(pair) != 2:
            raise rd.fail(
                f"{where}[{k}]", f"expected a pair [body, body], got {shown(pair)}"
            )
        a, b = (rd.lookup(index, name, f"{where}[{k}]", "body") for name in pair)
        if a == b:
            raise rd.fail(
                f"{where}[{k}]", f"expected two different bodies, got {shown(pair)}"
            )
        pairs.add((min(a, b), max(a, b)))
    return pairs


def _number(rd: Reader, table: dict, key: str, low: float, high: float, default):
    return rd.bounded(table, key, "[collision]", low, high) if key in table else default


def read_collision(rd: Reader, mech: Mechanism) -> Collision | None:
    """The :class:`~.model.Collision` of ``[collision]`` (None without the table);
    the per-body ``radius`` and ``layer`` are checked in any case."""
    data = mech.raw
    size = MAX_SIZE * mech.length_scale
    table = (
        rd.table(data["collision"], "[collision]", COLLISION_KEYS, set())
        if "collision" in data
        else {}
    )
    default = default_thickness(mech.length_scale)
    thickness = _number(rd, table, "thickness", 1e-9 * size, size, default)
    radii, layers = _body_sizes(rd, mech, thickness)
    if "collision" not in data:
        return None
    enabled = rd.boolean(table, "enable", "[collision]") if "enable" in table else True
    clearance = _number(rd, table, "clearance", 1e-9 * size, size, None)
    clearance = CLEARANCE_FRACTION * thickness if clearance is None else clearance
    weight = _number(rd, table, "weight", 0.0, MAX_WEIGHT, DEFAULT_WEIGHT)
    normal = _plane_normal(rd, mech, table)
    if normal is None and np.any(layers != 0.0):
        k = int(np.flatnonzero(layers != 0.0)[0])
        raise rd.fail(
            f"bodies[{k}].layer",
            "a layer is an offset along the plane's normal, and the revolute joints' "
            "axes are not all parallel; give [collision].normal",
        )
    offsets = np.outer(layers, np.zeros(3) if normal is None else normal)
    pairs = default_pairs(mech) - _pair_list(rd, table, "exclude", mech)
    pairs |= _pair_list(rd, table, "include", mech)
    return build_collision(mech, enabled, clearance, weight, radii, offsets, pairs)
