"""Design parameters of ``kind = "point"``: a named point's rest coordinate on its
body (:func:`point`); how a design places the point:
:func:`linkopt._engine.following.drive`."""

from __future__ import annotations

import numpy as np

from .design_moves import (
    ANCHOR,
    POINT,
    Context,
    Move,
    Parameter,
    bounds,
    check_bound_magnitude,
)
from .fields import field_name, shown


def point(ctx: Context, item: dict, where: str) -> Parameter:
    """One rest coordinate (``x``, ``y`` or ``z``, file units) of a named point given
    by ``position``, in its body's frame (the world axes at the rest pose, as a
    joint's coordinate). The parameter *is* that coordinate: it no longer follows the
    body's anchors (:func:`linkopt._engine.following.drive`), the point's other
    coordinates still follow its ``follow`` rule. Refused for a point given by
    ``joint`` (move the joint) and for a point on the ground (it never moves with the
    mechanism, so the parameter would move no traced point)."""
    rd = ctx.rd
    fields = {"name", "kind", "point", "coordinate", "min", "max"}
    rd.keys(item, where, fields, fields)
    index = {p["name"]: k for k, p in enumerate(ctx.points)}
    k = rd.lookup(index, item["point"], f"{where}.point", "point")
    point = ctx.points[k]
    if point["joint"] >= 0:
        raise rd.fail(
            f"{where}.point",
            f"point {point['name']!r} is given by 'joint' and follows that joint's "
            "anchor; expected a point given by 'position' (or a coordinate parameter "
            "of the joint)",
        )
    if point["body"] == ctx.ground:
        raise rd.fail(
            f"{where}.point",
            f"point {point['name']!r} is on the ground body, which never moves; "
            "expected a point on a moving body",
        )
    coord = item["coordinate"]
    if coord not in ("x", "y", "z"):
        raise rd.fail(
            f"{where}.coordinate",
            f"expected one of ['x', 'y', 'z'], got {shown(coord)}",
        )
    c = "xyz".index(coord)
    value = float(point["position"][c])
    label = f"{field_name(point['name'])}.{coord}"
    low, high = bounds(rd, item, where, value, label)
    check_bound_magnitude(ctx, where, (low, high), ANCHOR)
    return Parameter(value, low, high, True, [Move(k, POINT, np.eye(3)[c])], [])
