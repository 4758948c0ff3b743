"""The kinds of design parameter, each read into the anchor, axis and point moves it
makes per unit change (:class:`Move`): ``coordinate`` (with ``ties`` and symmetric
``mirror``/``copies``), ``length`` and ``radius``; the link angles and offsets
(``twist``, ``offset``) are in :mod:`.design_angles`, a named point's coordinate on
its body (``point``) in :mod:`.design_points`. :mod:`.design_space` turns the
moves into the DesignSpace's matrix.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from .._engine.model import AXIAL_JOINTS, COORDINATES
from .._engine.symmetry import MIRROR_TOL
from .design_moves import (
    ANCHOR,
    AXIS,
    Context,
    Move,
    Parameter,
    bounds,
    check_bound_magnitude,
    copies_list,
    positive_bounds,
)
from .fields import Reader, field_name, shown

KINDS = ("coordinate", "length", "radius", "twist", "offset", "point")


def read_parameter(ctx: Context, item: dict, where: str) -> Parameter:
    kind = item.get("kind", "coordinate")
    if not isinstance(kind, str) or kind not in KINDS:
        raise ctx.rd.fail(
            f"{where}.kind", f"expected one of {list(KINDS)}, got {shown(kind)}"
        )
    from . import design_angles, design_points  # they build on this module's readers

    reader = {
        "coordinate": _coordinate,
        "length": _length,
        "radius": _radius,
        "twist": design_angles.twist,
        "offset": design_angles.offset,
        "point": design_points.point,
    }[kind]
    par = reader(ctx, item, where)
    return replace(par, value=min(max(par.value, par.low), par.high))


# --- coordinate parameters (with ties and symmetric copies) ---------------------------


def _coordinate(ctx: Context, item: dict, where: str) -> Parameter:
    """One coordinate of a joint (group); ties and mirror/rotation copies move more."""
    rd = ctx.rd
    fields = {"name", "kind", "joint", "coordinate", "min", "max"}
    rd.keys(item, where, fields | {"mirror", "copies", "ties"}, fields - {"kind"})
    part, c = _coordinate_of(rd, item, where, "coordinate")
    group = _joint_group(ctx, item["joint"], f"{where}.joint", part)
    _check_axial(ctx, f"{where}.coordinate", group, part, item["joint"])
    joint = group[0]
    value = float(ctx.joints[joint]["anchor"][c])
    if part == AXIS:  # a component of the axis as written, not of the unit axis
        value = float(ctx.joints[joint]["axis"][c] * ctx.axis_lengths[joint])
    label = f"{field_name(ctx.name(joint))}.{item['coordinate']}"
    low, high = bounds(rd, item, where, value, label)
    check_bound_magnitude(ctx, where, (low, high), part)
    moves = [Move(g, part, np.eye(3)[c]) for g in group]
    moves += _ties(ctx, item, where, part, {(g, c) for g in group})
    moves += _coordinate_images(ctx, item, where, group, moves)
    return Parameter(value, low, high, part == ANCHOR, moves, [])


def _coordinate_of(rd: Reader, item: dict, where: str, key: str) -> tuple[int, int]:
    """``item[key]`` in :data:`COORDINATES`: (ANCHOR or AXIS, component 0..2)."""
    coord = item[key]
    if coord not in COORDINATES:
        raise rd.fail(
            f"{where}.{key}", f"expected one of {list(COORDINATES)}, got {shown(coord)}"
        )
    return (AXIS if coord.startswith("axis_") else ANCHOR), "xyz".index(coord[-1])


def _check_axial(ctx: Context, where: str, group: list[int], part: int, shown_as):
    if part == AXIS and any(ctx.joints[g]["type"] not in AXIAL_JOINTS for g in group):
        raise ctx.rd.fail(
            where,
            f"{shown(shown_as)}: only revolute, universal, prismatic and cylindrical "
            "joints have a movable axis",
        )


def _joint_group(ctx: Context, value, where: str, part: int) -> list[int]:
    """A joint name, or a list of joints that share their anchor (axis) at rest and
    move as one."""
    rd = ctx.rd
    names = value if isinstance(value, list) and value else [value]
    group = [rd.lookup(ctx.joint_index, name, where, "joint") for name in names]
    key = "axis" if part == AXIS else "anchor"
    tolerance = MIRROR_TOL if part == AXIS else ctx.tol
    for name, index in zip(names[1:], group[1:]):
        if (
            np.linalg.norm(ctx.joints[index][key] - ctx.joints[group[0]][key])
            > tolerance
        ):
            raise rd.fail(
                where,
                f"joints moved together must share their {key} at rest; {name!r} "
                f"differs from {names[0]!r} (use ties to move different anchors)",
            )
    if len(set(group)) != len(group):
        raise rd.fail(where, "a joint is listed twice")
    return group


def _ties(
    ctx: Context, item: dict, where: str, part: int, taken: set[tuple[int, int]]
) -> list[Move]:
    """``ties``: tables ``{joint, coordinate, factor}``; each moves that coordinate by
    ``factor`` times the parameter's change (anchors with anchors, axes with axes)."""
    if "ties" not in item:
        return []
    rd, value = ctx.rd, item["ties"]
    if not isinstance(value, list) or not value:
        raise rd.fail(
            f"{where}.ties",
            "expected a non-empty list of tables {joint, coordinate, factor}, got "
            f"{shown(value)}",
        )
    moves = []
    for i, tie in enumerate(value):
        at = f"{where}.ties[{i}]"
        fields = {"joint", "coordinate", "factor"}
        rd.table(tie, at, fields, fields)
        joint = rd.lookup(ctx.joint_index, tie["joint"], f"{at}.joint", "joint")
        tied_part, c = _coordinate_of(rd, tie, at, "coordinate")
        if tied_part != part:
            raise rd.fail(
                f"{at}.coordinate",
                "a tie moves the same kind of coordinate as its parameter (anchor "
                f"x/y/z with anchor, axis_* with axis), got {shown(tie['coordinate'])}",
            )
        _check_axial(ctx, f"{at}.coordinate", [joint], part, tie["joint"])
        factor = rd.number(tie, "factor", at)
        if factor == 0.0:
            raise rd.fail(f"{at}.factor", "expected a non-zero factor, got 0")
        if (joint, c) in taken:
            raise rd.fail(f"{at}", "ties a coordinate this parameter already drives")
        taken.add((joint, c))
        moves.append(Move(joint, part, factor * np.eye(3)[c]))
    return moves


def _coordinate_images(
    ctx: Context, item: dict, where: str, group: list[int], moves: list[Move]
) -> list[Move]:
    """The moves of the symmetric copies: ``mirror`` (a joint or coincident joints,
    under a mirror symmetry) or ``copies`` (each the image of the driven joint under
    some element of the symmetry, in any order); tied joints' images are the joints at
    the image positions."""
    rd = ctx.rd
    if "mirror" in item and "copies" in item:
        raise rd.fail(f"{where}.copies", "give mirror or copies, not both")
    part = moves[0].part
    if "mirror" in item:
        if ctx.symmetry is None or ctx.symmetry.kind != "mirror":
            raise rd.fail(
                f"{where}.mirror",
                "a mirror tie needs a [symmetry] table (normal and point)"
                + ("; under a rotation, use copies" if ctx.symmetry else ""),
            )
        named = _joint_group(ctx, item["mirror"], f"{where}.mirror", part)
        _check_mirror(ctx, f"{where}.mirror", group, named, part)
        return _image_moves(ctx, f"{where}.mirror", moves, named, group, 1)
    if "copies" not in item:
        return []
    images = []
    for i, entry in enumerate(copies_list(ctx, item, where)):
        at = f"{where}.copies[{i}]"
        named = _joint_group(ctx, entry, at, part)
        if set(named) & set(group):
            raise rd.fail(at, "a joint cannot be its own copy")
        fits = _elements(ctx, at, group[0], named[0], part)
        options = [_image_moves(ctx, at, moves, named, group, k) for k in fits]
        _check_unambiguous(ctx, at, options, named[0], group[0])
        images += options[0]
    return images


def _check_mirror(
    ctx: Context, where: str, group: list[int], named: list[int], part: int
) -> None:
    """The ``mirror`` twin is the mirror image of the driven joint (its anchor, or for
    an axis parameter its axis)."""
    rd, joint, twin = ctx.rd, group[0], named[0]
    if set(named) & set(group):
        raise rd.fail(where, "a joint cannot mirror itself")
    if part == AXIS and not _axis_fits(ctx, joint, twin, 1):
        raise rd.fail(
            where,
            f"axis of {ctx.name(twin)!r} is not the mirror image of the axis of "
            f"{ctx.name(joint)!r}",
        )
    gap = float(
        np.linalg.norm(ctx.symmetry.image(ctx.anchor(joint), 1) - ctx.anchor(twin))
    )
    if part == ANCHOR and gap > ctx.tol:
        raise rd.fail(
            where,
            f"anchor of {ctx.name(twin)!r} is not the mirror image of the anchor of "
            f"{ctx.name(joint)!r} ({gap:.3g} away, tolerance {ctx.tol:.3g})",
        )


def _axis_fits(ctx: Context, joint: int, twin: int, k: int) -> bool:
    image = ctx.symmetry.transform(k) @ ctx.joints[joint]["axis"]
    other = ctx.joints[twin]["axis"]
    return (
        min(np.linalg.norm(image - other), np.linalg.norm(image + other)) <= MIRROR_TOL
    )


def _elements(ctx: Context, where: str, joint: int, twin: int, part: int) -> list[int]:
    """The elements mapping ``joint``'s anchor onto ``twin``'s (and, for an axis part,
    its axis onto ``twin``'s); refused when there is none."""
    sym = ctx.symmetry
    gaps = [
        float(np.linalg.norm(sym.image(ctx.anchor(joint), k) - ctx.anchor(twin)))
        for k in range(1, sym.size)
    ]
    fits = [
        k
        for k, gap in enumerate(gaps, start=1)
        if gap <= ctx.tol and (part == ANCHOR or _axis_fits(ctx, joint, twin, k))
    ]
    if not fits:
        k = int(np.argmin(gaps)) + 1
        raise ctx.rd.fail(
            where,
            f"{'anchor' if part == ANCHOR else 'anchor and axis'} of "
            f"{ctx.name(twin)!r} is not an image of {ctx.name(joint)!r} under the "
            f"[symmetry]; the nearest, its {sym.words(k)}, is "
            f"{[float(v) for v in sym.image(ctx.anchor(joint), k)]}, {gaps[k - 1]:.3g} "
            f"away (tolerance {ctx.tol:.3g})",
        )
    return fits


def _check_unambiguous(ctx: Context, where: str, options: list, twin, joint) -> None:
    """Two elements mapping a joint onto its copy must move the copy alike."""

    def key(moves):
        return sorted((m.joint, m.part, tuple(np.round(m.vector, 12))) for m in moves)

    if any(key(o) != key(options[0]) for o in options[1:]):
        raise ctx.rd.fail(
            where,
            f"{ctx.name(twin)!r} is the image of {ctx.name(joint)!r} under several "
            "elements of the [symmetry] that move it differently (it lies on a "
            "symmetry axis or plane); expected an unambiguous copy",
        )


def _image_moves(
    ctx: Context, where: str, moves: list[Move], named, group, k: int
) -> list[Move]:
    """Each move carried over to the ``k``-th image: the driven group onto ``named``,
    any other joint onto the joints at its image position."""
    q = ctx.symmetry.transform(k)
    out = []
    for move in moves:
        if move.joint in group:
            targets = named
        else:
            targets = _joints_at_image(ctx, where, move, k)
        for t in targets:
            out.append(Move(t, move.part, _signed(ctx, q, move, t) @ np.eye(3)))
    return out


def _signed(ctx: Context, q, move: Move, target: int) -> np.ndarray:
    """``Q v``, with the sign that keeps an axis move along the target's own axis
    direction (an axis and its negative are the same line)."""
    vec = q @ move.vector
    if move.part == AXIS:
        image = q @ ctx.joints[move.joint]["axis"]
        return vec if image @ ctx.joints[target]["axis"] > 0 else -vec
    return vec


def _joints_at_image(ctx: Context, where: str, move: Move, k: int) -> list[int]:
    """The joints at the ``k``-th image of ``move.joint``'s anchor (for an axis move,
    those whose axis is the image axis)."""
    image = ctx.symmetry.image(ctx.anchor(move.joint), k)
    found = [
        i
        for i, j in enumerate(ctx.joints)
        if np.linalg.norm(j["anchor"] - image) <= ctx.tol
    ]
    if move.part == AXIS:
        axis = ctx.symmetry.transform(k) @ ctx.joints[move.joint]["axis"]
        found = [i for i in found if abs(abs(axis @ ctx.joints[i]["axis"]) - 1) < 1e-9]
    if not found or move.joint in found:
        problem = "is a joint's own image" if found else "has no joint at its image"
        raise ctx.rd.fail(
            where,
            f"tied joint {ctx.name(move.joint)!r} {problem} "
            f"({ctx.symmetry.words(k)}: {[float(v) for v in image]})",
        )
    return found


# --- link lengths ---------------------------------------------------------------------


def _length(ctx: Context, item: dict, where: str) -> Parameter:
    """``|centroid(to) - from|`` at rest; ``to`` moves along the rest direction ``u``
    (fixed from the initial design: the parameter changes the length, never the
    direction), and follows every move of ``from`` (composed in
    :mod:`.design_space`), so the parameter stays the link length whatever other
    parameters do."""
    rd = ctx.rd
    fields = {"name", "kind", "body", "from", "to", "min", "max"}
    rd.keys(item, where, fields | {"copies"}, fields)
    body = rd.lookup(ctx.body_index, item["body"], f"{where}.body", "body")
    source, targets = link_joints(ctx, item, where, body)
    offset = np.mean([ctx.anchor(t) for t in targets], axis=0) - ctx.anchor(source)
    value = float(np.linalg.norm(offset))
    if value <= ctx.tol:
        raise rd.fail(
            f"{where}.to",
            f"zero-length link: the anchors of {shown(item['from'])} and "
            f"{shown(item['to'])} coincide at rest; expected a positive length",
        )
    low, high = positive_bounds(ctx, item, where, value, "link length")
    unit = offset / value
    moves = [Move(t, ANCHOR, unit) for t in targets]
    links = [(source, targets)]
    copies = _length_copies(ctx, item, where, (source, targets), unit)
    for k, image_source, images in copies:
        moves += [Move(t, ANCHOR, ctx.symmetry.transform(k) @ unit) for t in images]
        links.append((image_source, images))
    return Parameter(value, low, high, True, moves, links)


def link_joints(
    ctx: Context, item: dict, where: str, body: int
) -> tuple[int, list[int]]:
    """``from`` (one joint) and ``to`` (a joint or a list), all joints of ``body``."""
    rd = ctx.rd
    source = rd.lookup(ctx.joint_index, item["from"], f"{where}.from", "joint")
    names = item["to"] if isinstance(item["to"], list) and item["to"] else [item["to"]]
    targets = [rd.lookup(ctx.joint_index, n, f"{where}.to", "joint") for n in names]
    if len(set(targets)) != len(targets) or source in targets:
        raise rd.fail(f"{where}.to", "a joint is listed twice (or is also from)")
    for t in set(ctx.coincident(source)) & set(targets):
        raise rd.fail(
            f"{where}.to",
            f"zero-length link: {ctx.name(t)!r} and {ctx.name(source)!r} share their "
            "anchor at rest; expected a positive length",
        )
    for key, j in [("from", source)] + [("to", t) for t in targets]:
        if body not in ctx.joints[j]["bodies"]:
            raise rd.fail(
                f"{where}.{key}",
                f"joint {ctx.name(j)!r} is not a joint of body {shown(item['body'])}",
            )
    return source, targets


def _length_copies(
    ctx: Context, item: dict, where: str, link: tuple[int, list[int]], unit
) -> list[tuple[int, int, list[int]]]:
    """For each body in ``copies``: the element ``k`` and the body's joints at the
    images of ``from`` and ``to`` under it."""
    if "copies" not in item:
        return []
    out = []
    for i, name in enumerate(copies_list(ctx, item, where)):
        at = f"{where}.copies[{i}]"
        body = ctx.rd.lookup(ctx.body_index, name, at, "body")
        options = _link_images(ctx, body, link)
        if not options:
            raise ctx.rd.fail(
                at,
                f"body {name!r} has no joints at an image of {ctx.name(link[0])!r} "
                f"and {ctx.name(link[1][0])!r} under the [symmetry] (tolerance "
                f"{ctx.tol:.3g}); expected an image of body {shown(item['body'])}",
            )
        k, image_source, images = options[0]
        for other in options[1:]:
            direction = ctx.symmetry.transform(other[0]) @ unit
            same = (other[1], sorted(other[2])) == (image_source, sorted(images))
            if not same or not np.allclose(
                direction, ctx.symmetry.transform(k) @ unit, atol=1e-12
            ):
                raise ctx.rd.fail(
                    at,
                    f"body {name!r} is the image of {shown(item['body'])} under "
                    "several elements of the [symmetry] that move it differently; "
                    "expected an unambiguous copy",
                )
        for own in sorted(set(images) & set(ctx.coincident_all(link[1]))):
            raise ctx.rd.fail(
                at,
                f"joint {ctx.name(own)!r} is its own {ctx.symmetry.words(k)}; a "
                "symmetric length cannot move it along both links",
            )
        out.append((k, image_source, images))
    return out


def _link_images(ctx: Context, body: int, link) -> list[tuple[int, int, list[int]]]:
    """Every element ``k`` under which ``body`` has joints at the images of the link's
    ``from`` and ``to`` joints, with those joints."""
    options = []
    for k in range(1, ctx.symmetry.size):
        source = _body_joint_at(ctx, body, link[0], k)
        images = [_body_joint_at(ctx, body, t, k) for t in link[1]]
        if source >= 0 and min(images) >= 0:
            options.append((k, source, images))
    return options


def _body_joint_at(ctx: Context, body: int, joint: int, k: int) -> int:
    """The joint of ``body`` at the image of ``joint``'s anchor under element ``k``,
    or -1."""
    image = ctx.symmetry.image(ctx.anchor(joint), k)
    for i, j in enumerate(ctx.joints):
        if body in j["bodies"] and np.linalg.norm(j["anchor"] - image) <= ctx.tol:
            return i
    return -1


def _body(ctx: Context, body: int) -> str:
    return next(name for name, b in ctx.body_index.items() if b == body)


# --- radii ----------------------------------------------------------------------------


def _radius(ctx: Context, item: dict, where: str) -> Parameter:
    """The common distance of ``joints`` from the axis (``center``, ``axis``); each
    anchor moves along its own rest radial direction."""
    rd = ctx.rd
    fields = {"name", "kind", "joints", "center", "axis", "min", "max"}
    rd.keys(item, where, fields, fields)
    names = item["joints"]
    if not isinstance(names, list) or not names:
        raise rd.fail(
            f"{where}.joints",
            f"expected a non-empty list of joints, got {shown(names)}",
        )
    joints = [rd.lookup(ctx.joint_index, n, f"{where}.joints", "joint") for n in names]
    if len(set(joints)) != len(joints):
        raise rd.fail(f"{where}.joints", "a joint is listed twice")
    center = rd.vector(item, "center", where)
    ctx.check_position(f"{where}.center", center)
    axis = rd.direction(item, "axis", where)
    radial = [_radial(ctx, f"{where}.joints", j, center, axis) for j in joints]
    value = float(np.linalg.norm(radial[0]))
    for j, r in zip(joints, radial):
        if abs(np.linalg.norm(r) - value) > ctx.tol:
            raise rd.fail(
                f"{where}.joints",
                f"joint {ctx.name(j)!r} is {np.linalg.norm(r):.12g} from the axis, "
                f"{ctx.name(joints[0])!r} {value:.12g}; expected joints on one circle",
            )
    low, high = positive_bounds(ctx, item, where, value, "radius")
    moves = [Move(j, ANCHOR, r / np.linalg.norm(r)) for j, r in zip(joints, radial)]
    return Parameter(value, low, high, True, moves, [])


def _radial(ctx: Context, where: str, joint: int, center, axis) -> np.ndarray:
    offset = ctx.anchor(joint) - center
    radial = offset - (offset @ axis) * axis
    if np.linalg.norm(radial) <= ctx.tol:
        raise ctx.rd.fail(
            where,
            f"joint {ctx.name(joint)!r} lies on the axis; a radius needs joints off "
            "the axis",
        )
    return radial
