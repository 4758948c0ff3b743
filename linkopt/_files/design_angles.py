"""Link angles and offsets between two joint axes of one link (Denavit–Hartenberg's
twist and offset), read into design parameters.

* ``twist``: the angle between the axes of joints ``from`` and ``to``, in (0, π). The
  ``to`` joint (and every joint sharing its anchor) turns about the common normal of
  the two axes, the line through the foot of that normal on ``from``'s axis along
  ``n = a_from × a_to / |a_from × a_to|``, fixed from the initial design. The turn keeps
  the distance between the two axes (the offset along ``n``) and every distance to
  the line: in a spherical mechanism (every axis through one centre) the foot is the
  centre, so the turned axis still passes through it and the anchor stays on its
  sphere. A turn is not linear in the parameter, so it is the one part of a design
  space outside its matrix (:class:`~.model.Turns`, applied in
  :func:`~.geometry.moved_joints`).
* ``offset``: the distance between two parallel axes; ``to`` moves along the
  perpendicular from ``from``'s axis, a linear move like a ``length``.

Twists compose like lengths: the joints a twist turns also turn with every twist that
turns its ``from`` joint (a chain of link angles from the ground). A twist's joints
must not be moved by a linear parameter (its centre and normal would not follow).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .design_kinds import link_joints
from .design_moves import ANCHOR, Context, Move, Parameter, bounds, positive_bounds
from .fields import shown

#: Axes closer to parallel than this (|sin| of their angle) have no twist (an offset).
PARALLEL_SIN = 1e-9


@dataclass(frozen=True)
class Turn:
    """A twist: joints ``targets`` (and those sharing their anchor) turn about the line
    through ``center`` along ``normal`` as the parameter changes; ``source`` is the
    ``from`` joint."""

    source: int
    targets: list[int]
    center: np.ndarray
    normal: np.ndarray


def _two_axes(ctx: Context, item: dict, where: str) -> tuple[int, int]:
    rd = ctx.rd
    fields = {"name", "kind", "body", "from", "to", "min", "max"}
    rd.keys(item, where, fields, fields)
    body = rd.lookup(ctx.body_index, item["body"], f"{where}.body", "body")
    if not isinstance(item["to"], str):
        raise rd.fail(
            f"{where}.to", f"expected one joint name, got {shown(item['to'])}"
        )
    source, (target,) = link_joints(ctx, item, where, body)
    for key, j in (("from", source), ("to", target)):
        if not np.any(ctx.joints[j]["axis"]) or ctx.joints[j]["type"] == "spherical":
            raise rd.fail(
                f"{where}.{key}",
                f"joint {ctx.name(j)!r} has no axis; a {item['kind']} is measured "
                "between two joint axes",
            )
    return source, target


def twist(ctx: Context, item: dict, where: str) -> Parameter:
    """``kind = "twist"``: the angle between the axes of ``from`` and ``to``."""
    source, target = _two_axes(ctx, item, where)
    a, b = ctx.joints[source]["axis"], ctx.joints[target]["axis"]
    cross = np.cross(a, b)
    if np.linalg.norm(cross) <= PARALLEL_SIN:
        raise ctx.rd.fail(
            f"{where}.to",
            f"the axes of {ctx.name(source)!r} and {ctx.name(target)!r} are parallel "
            'at rest and have no twist; their distance is kind = "offset"',
        )
    value = float(np.arctan2(np.linalg.norm(cross), a @ b))
    low, high = bounds(ctx.rd, item, where, value, "the twist")
    if low <= 0.0 or high >= np.pi:
        raise ctx.rd.fail(
            f"{where}.{'min' if low <= 0.0 else 'max'}",
            f"a twist lies strictly between 0 and pi (the normal of two parallel axes "
            f"is lost), got min={low:g} and max={high:g}",
        )
    normal = cross / np.linalg.norm(cross)
    center = _foot(ctx.anchor(source), a, ctx.anchor(target), b)
    turn = Turn(source, [target], center, normal)
    return Parameter(value, low, high, False, [], [], (turn,))


def _foot(x1: np.ndarray, a: np.ndarray, x2: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The foot on line ``x1 + s a`` of the common normal to line ``x2 + t b``
    (non-parallel unit directions)."""
    w = x1 - x2
    ab, aw, bw = a @ b, a @ w, b @ w
    s = (ab * bw - aw) / (1.0 - ab * ab)
    return x1 + s * a


def offset(ctx: Context, item: dict, where: str) -> Parameter:
    """``kind = "offset"``: the distance between the parallel axes of ``from`` and
    ``to``; ``to`` moves along the perpendicular from ``from``'s axis (and follows
    every move of ``from``, as a length's ``to`` does)."""
    source, target = _two_axes(ctx, item, where)
    a, b = ctx.joints[source]["axis"], ctx.joints[target]["axis"]
    if np.linalg.norm(np.cross(a, b)) > PARALLEL_SIN:
        raise ctx.rd.fail(
            f"{where}.to",
            f"the axes of {ctx.name(source)!r} and {ctx.name(target)!r} are not "
            "parallel at rest; expected parallel axes (their angle is kind = "
            '"twist")',
        )
    gap = ctx.anchor(target) - ctx.anchor(source)
    across = gap - (gap @ a) * a
    value = float(np.linalg.norm(across))
    if value <= ctx.tol:
        raise ctx.rd.fail(
            f"{where}.to",
            f"the axes of {ctx.name(source)!r} and {ctx.name(target)!r} coincide at "
            "rest; expected a positive offset",
        )
    low, high = positive_bounds(ctx, item, where, value, "offset")
    moves = [Move(target, ANCHOR, across / value)]
    return Parameter(value, low, high, True, moves, [(source, [target])])


def turn_joints(
    ctx: Context, where: list[str], turns: list[tuple[int, Turn]]
) -> list[tuple[int, Turn, np.ndarray]]:
    """Each turn (parameter index, :class:`Turn`) with the joints it turns: its
    targets, the joints sharing their anchors and, transitively, the joints of every
    turn whose ``from`` joint it turns. Ordered downstream first (the order
    :class:`~.model.Turns` applies them in); a loop of twists is refused."""
    own = {id(t): set(ctx.coincident_all(t.targets)) for _, t in turns}
    moved = {id(t): set(own[id(t)]) for _, t in turns}
    for _ in turns:  # transitive closure over at most len(turns) levels
        for _, t in turns:
            for _, other in turns:
                if other.source in moved[id(t)]:
                    moved[id(t)] |= moved[id(other)]
    for k, (_, t) in enumerate(turns):
        if t.source in moved[id(t)]:
            raise ctx.rd.fail(
                where[k],
                "twists form a loop (each link's from joint is turned by another's); "
                "expected a chain from the ground",
            )
    ordered = sorted(turns, key=lambda kt: len(moved[id(kt[1])]))
    out = []
    for k, t in ordered:
        mask = np.zeros(len(ctx.joints))
        mask[sorted(moved[id(t)])] = 1.0
        out.append((k, t, mask))
    return out
