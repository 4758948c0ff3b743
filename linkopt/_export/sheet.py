"""Sheet drawings of a planar mechanism's links, DXF (ezdxf) and SVG, for a laser
cutter or a waterjet.

Each link (a body; a welded part is its own link) is one closed outline: the convex
hull of circles of radius ``JOINT_FACTOR · r`` around its places (joint anchors and
named points, :func:`linkopt._export.tree.body_anchors`), ``r`` the radius of its
capsules (:func:`linkopt._export.tree.body_capsules`: the ``[collision]`` radius, or
half of ``--thickness``), so two places make a slot and more a rounded plate. Each
joint on the link is a hole of radius ``HOLE_FRACTION · r`` at its anchor; the link's
name stands at its centroid and each capsule's centre distance at the capsule's
middle. Every link has its own layer (DXF) or group (SVG), named after the body.

The drawing lies in the plane normal to the joints' common axis, at the rest pose of
the design, in file units: the coordinates are the anchors' components along two
in-plane axes (the world axes when the axis is a world axis, so a mechanism in the
``z = 0`` plane is drawn at its ``x, y``). The links are drawn where they sit in the
assembly, so they overlap; a user nests them for cutting. SVG's ``y`` axis points
down, so the SVG file holds ``(x, -y)`` and its picture is not mirrored.

A spatial mechanism has no such plane and is refused (:func:`sheet_plane` names the
joint that leaves it); a prismatic joint is drawn as a hole at its anchor like the
others (its guide is not drawn).
"""

from __future__ import annotations

import io
import math
from dataclasses import dataclass
from pathlib import Path
from xml.sax.saxutils import escape, quoteattr

import numpy as np
from jaxtyping import Float

from .._engine.links import segments
from .._engine.model import Mechanism
from .._engine.welding import parts
from .._errors import InputError, MechanismFileError
from .._folders import write_atomic
from .meshes import JOINT_FACTOR, check_thickness
from .tree import Rest, body_anchors, metres_per_unit, rest

#: A joint's hole radius, as a fraction of its link's capsule radius.
HOLE_FRACTION = 0.5
#: Out-of-plane spread (reference lengths) and axis misalignment (sine) tolerated.
PLANE_TOLERANCE = 1e-9
#: DXF ``$INSUNITS`` codes of the units an export understands.
DXF_UNITS = {"m": 6, "dm": 14, "cm": 5, "mm": 4, "um": 13, "km": 7, "in": 1, "ft": 2}
#: Rotary joint families (their axis is the plane's normal).
ROTARY = ("revolute", "cylindrical")


@dataclass(frozen=True)
class Link:
    """One link's outline, holes and labels in the sheet's plane (file units)."""

    name: str
    places: Float[np.ndarray, "k 2"]  # centres of the outline's rounded corners
    radius: float  # the outline's corner radius
    holes: Float[np.ndarray, "h 2"]
    hole_joints: tuple[str, ...]
    hole_radius: float
    #: (from, to, centre distance) of each capsule, from and to in ``places``
    distances: tuple[tuple[int, int, float], ...]


@dataclass(frozen=True)
class Sheet:
    """The links of a planar mechanism at the rest pose of one design."""

    links: tuple[Link, ...]
    basis: Float[np.ndarray, "2 3"]  # world directions of the drawing's x and y
    units: str  # the file's unit (``metres_per_unit``'s name)
    metres_per_unit: float


def _refuse(mech: Mechanism, joint: int, why: str) -> InputError:
    return MechanismFileError(
        mech.source,
        f"joints[{joint}]",
        f"{mech.joint_names[joint]!r} {why}: a sheet drawing (dxf, svg) needs a planar "
        "mechanism; export stl or glb instead",
    )


def sheet_plane(mech: Mechanism, rest_pose: Rest) -> Float[np.ndarray, " 3"]:
    """The unit normal of the joints' common axis, when every joint is revolute,
    cylindrical, prismatic or fixed, the rotary axes are parallel, the prismatic axes
    lie in the plane, and every anchor and named point lies in one plane normal to
    the axis; else :class:`~linkopt.MechanismFileError` naming the first joint that
    does not."""
    types = mech.joint_types
    for j, kind in enumerate(types):
        if kind not in (*ROTARY, "prismatic", "fixed"):
            raise _refuse(mech, j, f"is {kind} (it turns out of any one plane)")
    rotary = [j for j, kind in enumerate(types) if kind in ROTARY]
    if not rotary:
        raise InputError(
            f"{mech.source}: no revolute joint gives a common axis: a sheet drawing "
            "(dxf, svg) needs a planar mechanism; export stl or glb instead"
        )
    normal = rest_pose.axes[rotary[0]] / np.linalg.norm(rest_pose.axes[rotary[0]])
    for j in rotary:
        if np.linalg.norm(np.cross(rest_pose.axes[j], normal)) > PLANE_TOLERANCE:
            raise _refuse(mech, j, "turns about an axis not parallel to the first's")
    for j, kind in enumerate(types):
        if kind == "prismatic" and abs(rest_pose.axes[j] @ normal) > PLANE_TOLERANCE:
            raise _refuse(mech, j, "slides out of the plane normal to the common axis")
    height = rest_pose.anchors @ normal - rest_pose.anchors[rotary[0]] @ normal
    off = np.flatnonzero(np.abs(height) > PLANE_TOLERANCE * mech.length_scale)
    if len(off):
        raise _refuse(mech, int(off[0]), f"lies {height[off[0]]:.3g} off the plane")
    return normal


def basis(normal: Float[np.ndarray, " 3"]) -> Float[np.ndarray, "2 3"]:
    """Two orthonormal in-plane axes: the other two world axes, in order, when the
    normal is a world axis; else a right-handed pair."""
    k = int(np.argmax(np.abs(normal)))
    if abs(normal[k]) >= 1.0 - 1e-12:
        return np.eye(3)[[i for i in range(3) if i != k]]
    first = np.cross(normal, np.eye(3)[int(np.argmin(np.abs(normal)))])
    first /= np.linalg.norm(first)
    return np.stack([first, np.cross(normal, first)])


def _radius(mech: Mechanism, body: int, thickness: float | None) -> float:
    if thickness is not None or mech.collision is None:
        return 0.5 * check_thickness(mech, thickness)
    return float(mech.collision.body_radii[body])


def _link(mech, rest_pose, body, axes, thickness) -> Link:
    r = _radius(mech, body, thickness)
    places = body_anchors(mech, rest_pose, body) @ axes.T
    joints = [int(j) for j in mech.joints_on(body)]
    pairs = segments(places) if len(places) > 1 else []
    return Link(
        name=mech.body_names[body],
        places=places,
        radius=JOINT_FACTOR * r,
        holes=rest_pose.anchors[joints] @ axes.T if joints else np.zeros((0, 2)),
        hole_joints=tuple(mech.joint_names[j] for j in joints),
        hole_radius=HOLE_FRACTION * r,
        distances=tuple(
            (a, b, float(np.linalg.norm(places[a] - places[b]))) for a, b in pairs
        ),
    )


def sheet(mech: Mechanism, design=None, *, thickness=None) -> Sheet:
    """The sheet drawing of ``design`` (None: the file's) at rest; ``thickness`` None:
    the ``[collision]`` radii, or the default thickness (module docstring)."""
    mech = parts(mech)
    rest_pose = rest(mech, design)
    axes = basis(sheet_plane(mech, rest_pose))
    s, unit = metres_per_unit(mech)
    links = tuple(
        _link(mech, rest_pose, b, axes, thickness) for b in range(mech.num_bodies)
    )
    return Sheet(links, axes, unit, s)


# ---- outlines -----------------------------------------------------------------------


def hull(points: Float[np.ndarray, "k 2"]) -> Float[np.ndarray, "h 2"]:
    """The convex hull's corners, counter-clockwise (Andrew's monotone chain);
    collinear and repeated points left out."""
    pts = sorted({(float(x), float(y)) for x, y in points})
    if len(pts) <= 2:
        return np.array(pts)

    def half(seq):
        out: list = []
        for p in seq:
            while len(out) >= 2 and _cross(out[-2], out[-1], p) <= 0:
                out.pop()
            out.append(p)
        return out[:-1]

    return np.array(half(pts) + half(pts[::-1]))


def _cross(o, a, b) -> float:
    return (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])


def outline(link: Link) -> list[tuple[np.ndarray, np.ndarray, float]]:
    """The rounded hull as arcs: per hull corner ``(arc start, arc end, turn)``,
    counter-clockwise, ``turn`` the arc's angle (rad); a straight edge joins each
    arc's end to the next one's start. Empty for a link of one place (a circle)."""
    corners = hull(link.places)
    if len(corners) < 2:
        return []
    k = len(corners)
    normals = []
    for i in range(k):
        edge = corners[(i + 1) % k] - corners[i]
        normals.append(np.array([edge[1], -edge[0]]) / np.linalg.norm(edge))
    arcs = []
    for i in range(k):
        before, after = normals[i - 1], normals[i]
        turn = math.atan2(
            before[0] * after[1] - before[1] * after[0], before @ after
        ) % (2 * math.pi)  # > 0: the hull has no collinear corners
        c = corners[i]
        arcs.append((c + link.radius * before, c + link.radius * after, turn))
    return arcs


# ---- DXF ------------------------------------------------------------------------


def _layer_name(name: str, taken: set) -> str:
    """``name`` with the characters DXF forbids in a layer name replaced, unique."""
    clean = "".join("_" if c in '<>/\\":;?*|=`' else c for c in name) or "link"
    out, n = clean, 1
    while out.lower() in taken:
        n += 1
        out = f"{clean}_{n}"
    taken.add(out.lower())
    return out


def _text_height(drawing: Sheet) -> float:
    return max(min(link.radius for link in drawing.links), 1e-9) * 0.6


def require_ezdxf() -> None:
    """:class:`InputError` when ezdxf (the ``export`` extra) is missing."""
    try:
        import ezdxf  # noqa: F401
    except ImportError:
        raise InputError("DXF export needs ezdxf: pip install -e '.[export]'") from None


def check_planar(mech: Mechanism, design=None) -> None:
    """:func:`sheet_plane`'s refusal of a spatial mechanism, before anything is
    drawn."""
    mech = parts(mech)
    sheet_plane(mech, rest(mech, design))


def write_dxf(drawing: Sheet, path: Path) -> None:
    """The drawing as a DXF file (R2010), one layer per link (module docstring)."""
    require_ezdxf()
    import ezdxf
    from ezdxf.enums import TextEntityAlignment

    doc = ezdxf.new("R2010")
    doc.header["$INSUNITS"] = DXF_UNITS.get(drawing.units.split()[0], 0)
    doc.header["$MEASUREMENT"] = 0 if drawing.units in ("in", "ft") else 1
    msp = doc.modelspace()
    taken: set = set()
    height = _text_height(drawing)
    for k, link in enumerate(drawing.links):
        layer = _layer_name(link.name, taken)
        doc.layers.add(layer, color=1 + k % 254)
        attribs = {"layer": layer}
        arcs = outline(link)
        if arcs:
            points = []
            for start, end, turn in arcs:
                points.append((*start, math.tan(turn / 4)))
                points.append((*end, 0.0))
            msp.add_lwpolyline(points, format="xyb", close=True, dxfattribs=attribs)
        else:
            msp.add_circle(tuple(link.places[0]), link.radius, dxfattribs=attribs)
        for centre in link.holes:
            msp.add_circle(tuple(centre), link.hole_radius, dxfattribs=attribs)
        for text, at in _labels(drawing, link):
            entity = msp.add_text(text, height=height, dxfattribs=attribs)
            entity.set_placement(tuple(at), align=TextEntityAlignment.MIDDLE_CENTER)
    stream = io.StringIO()
    doc.write(stream)
    write_atomic(path, stream.getvalue())


def _labels(drawing: Sheet, link: Link) -> list[tuple[str, np.ndarray]]:
    """The link's name at its centroid, each centre distance (in the file's unit)
    beside its capsule's middle, 1.2 text heights off the line."""
    unit = drawing.units.split()[0]
    out = [(link.name, np.mean(link.places, axis=0))]
    off = 1.2 * _text_height(drawing)
    for a, b, d in link.distances:
        along = (link.places[b] - link.places[a]) / d
        at = 0.5 * (link.places[a] + link.places[b]) + off * np.array(
            [-along[1], along[0]]
        )
        out.append((f"{d:.6g} {unit}", at))
    return out


# ---- SVG ------------------------------------------------------------------------

#: SVG's length units, with millimetres per unit (a file unit it lacks is drawn in mm).
SVG_UNITS = {"mm": 1.0, "cm": 10.0, "in": 25.4}


def _flip(p) -> str:
    return f"{p[0]:.17g} {-p[1]:.17g}"


def _path(link: Link) -> str:
    arcs = outline(link)
    r = f"{link.radius:.17g}"
    commands = [f"M {_flip(arcs[0][0])}"]
    for i, (_, end, turn) in enumerate(arcs):
        large = 1 if turn > math.pi + 1e-12 else 0
        commands.append(f"A {r} {r} 0 {large} 0 {_flip(end)}")  # y flipped: clockwise
        commands.append(f"L {_flip(arcs[(i + 1) % len(arcs)][0])}")
    return " ".join(commands) + " Z"


def svg_text(drawing: Sheet) -> str:
    """The drawing as an SVG document (module docstring): one ``<g>`` per link (an
    Inkscape layer named after it), its outline a ``<path class="outline">``, its
    holes ``<circle class="hole" data-joint=...>``, its labels ``<text>``."""
    every = np.concatenate([link.places for link in drawing.links])
    pad = max(link.radius for link in drawing.links)
    low, high = every.min(axis=0) - pad, every.max(axis=0) + pad
    size = high - low
    unit = drawing.units.split()[0]
    shown = unit if unit in SVG_UNITS else "mm"
    scale = drawing.metres_per_unit * 1000 / SVG_UNITS[shown]
    height = _text_height(drawing)
    lines = [
        '<svg xmlns="http://www.w3.org/2000/svg" '
        'xmlns:inkscape="http://www.inkscape.org/namespaces/inkscape" '
        f'width="{size[0] * scale:.6g}{shown}" height="{size[1] * scale:.6g}{shown}" '
        f'viewBox="{low[0]:.17g} {-high[1]:.17g} {size[0]:.17g} {size[1]:.17g}">',
        f"<!-- linkopt sheet drawing; file units: {escape(drawing.units)}; "
        "y negated (SVG's y points down) -->",
    ]
    stroke = f'fill="none" stroke="black" stroke-width="{height / 10:.6g}"'
    for link in drawing.links:
        name = quoteattr(link.name)
        lines.append(f'<g inkscape:groupmode="layer" inkscape:label={name} id={name}>')
        if len(hull(link.places)) >= 2:
            lines.append(f'<path class="outline" {stroke} d="{_path(link)}"/>')
        else:
            c = link.places[0]
            lines.append(
                f'<circle class="outline" {stroke} cx="{c[0]:.17g}" '
                f'cy="{-c[1]:.17g}" r="{link.radius:.17g}"/>'
            )
        for joint, c in zip(link.hole_joints, link.holes):
            lines.append(
                f'<circle class="hole" data-joint={quoteattr(joint)} {stroke} '
                f'cx="{c[0]:.17g}" cy="{-c[1]:.17g}" r="{link.hole_radius:.17g}"/>'
            )
        for text, at in _labels(drawing, link):
            lines.append(
                f'<text x="{at[0]:.17g}" y="{-at[1]:.17g}" font-size="{height:.6g}" '
                f'text-anchor="middle" dominant-baseline="middle">{escape(text)}</text>'
            )
        lines.append("</g>")
    lines.append("</svg>")
    return "\n".join(lines) + "\n"


def _summary(kind: str, drawing: Sheet, path: Path) -> dict:
    return {
        "format": kind,
        "links": len(drawing.links),
        "holes": sum(len(link.holes) for link in drawing.links),
        "metres_per_unit": drawing.metres_per_unit,
        "files": [str(path)],
    }


def export_dxf(mech: Mechanism, path, design=None, *, thickness=None) -> dict:
    """Write the sheet drawing of a planar mechanism at ``design`` (None: the file's)
    as DXF to ``path`` (module docstring: a layer per link, outlines, holes, names and
    centre distances, file units); ``thickness``: the link diameter (None: the
    ``[collision]`` radii, else 4 % of the reference length). Returns a summary;
    :class:`~linkopt.MechanismFileError` for a spatial mechanism."""
    drawing = sheet(mech, design, thickness=thickness)
    write_dxf(drawing, Path(path))
    return _summary("dxf", drawing, Path(path))


def export_svg(mech: Mechanism, path, design=None, *, thickness=None) -> dict:
    """As :func:`export_dxf`, as SVG (one group per link; ``y`` negated, SVG's
    ``y`` pointing down)."""
    drawing = sheet(mech, design, thickness=thickness)
    write_atomic(Path(path), svg_text(drawing))
    return _summary("svg", drawing, Path(path))
