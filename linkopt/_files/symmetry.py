"""``[symmetry]``: a mirror plane, or an n-fold rotation about an axis, optionally with
a mirror plane containing the axis, read into a
:class:`~linkopt._engine.symmetry.Symmetry`.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from .._engine.symmetry import MAX_ORDER, MIRROR_TOL, Symmetry
from .fields import Reader, shown


def read_symmetry(
    rd: Reader, data: dict, position: Callable[[dict, str, str], np.ndarray]
) -> Symmetry | None:
    """``[symmetry]``: ``normal`` and ``point`` (a mirror plane; ``kind = "mirror"``
    optional), or ``kind = "rotation"`` with ``axis``, ``point``, ``order`` and
    optionally ``normal`` (a mirror plane containing the axis).
    ``position(table, key, where)`` reads a checked position."""
    if "symmetry" not in data:
        return None
    raw = data["symmetry"]
    kind = raw.get("kind", "mirror") if isinstance(raw, dict) else "mirror"
    if kind == "rotation":
        return _read_rotation(rd, raw, position)
    if kind != "mirror":
        raise rd.fail(
            "[symmetry].kind", f"expected 'mirror' or 'rotation', got {shown(kind)}"
        )
    table = rd.table(
        raw, "[symmetry]", {"kind", "normal", "point"}, {"normal", "point"}
    )
    normal = rd.direction(table, "normal", "[symmetry]")
    return Symmetry(normal, position(table, "point", "[symmetry]"))


def _read_rotation(rd: Reader, raw: dict, position) -> Symmetry:
    fields = {"kind", "axis", "point", "order"}
    table = rd.table(raw, "[symmetry]", fields | {"normal"}, fields)
    order = rd.integer(table, "order", "[symmetry]", 2, MAX_ORDER)
    axis = rd.direction(table, "axis", "[symmetry]")
    point = position(table, "point", "[symmetry]")
    if "normal" not in table:
        return Symmetry(axis, point, "rotation", order)
    normal = rd.direction(table, "normal", "[symmetry]")
    if abs(normal @ axis) > MIRROR_TOL:
        raise rd.fail(
            "[symmetry].normal",
            "the mirror plane of a rotation must contain its axis: expected a normal "
            "perpendicular to axis",
        )
    return Symmetry(axis, point, "rotation", order, normal)
