"""What the export formats share: rest geometry, units, the spanning tree, joint
coordinates.

A mechanism file is a graph of bodies (nodes) and joints (edges). MJCF and URDF are
kinematic trees, so every export picks a spanning tree rooted at the ground
(:func:`spanning_tree`). Each tree joint becomes a short sequence of elementary
degrees of freedom (:class:`Dof`: hinge, slide, ball) in the child body; the joints
left out close the loops (MJCF writes them as equality constraints, URDF refuses them).

Frames: every body sits at the identity orientation at rest with its origin at
``Mechanism.body_origins`` (:mod:`linkopt._engine.model`), so a joint's rest axes are
the same vectors in both of its bodies' frames and in the world.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from jaxtyping import Float

from .._engine import links, programs
from .._engine.geometry import design_array, geometry
from .._engine.links import body_places, segments
from .._engine.model import Mechanism
from .._engine.rotations import np_axis_angle_matrix, np_from_matrix, np_matrix
from .._errors import MechanismFileError

#: Metres per file unit, by the ``[mechanism] units`` strings an export understands.
METRES_PER_UNIT: dict[str, float] = {
    "m": 1.0,
    "dm": 0.1,
    "cm": 0.01,
    "mm": 1e-3,
    "um": 1e-6,
    "km": 1e3,
    "in": 0.0254,
    "ft": 0.3048,
}

#: Joint families in the order the spanning tree prefers them as tree edges: the ones
#: an equality constraint cannot close directly first (their closures need an extra
#: body), revolute next, spherical last (a single ``connect`` closes it).
_TREE_PREFERENCE = ("fixed", "universal", "prismatic", "cylindrical", "revolute")


@dataclass(frozen=True)
class Rest:
    """Rest pose of one design, world frame, file units (unit vectors for axes)."""

    anchors: Float[np.ndarray, "J 3"]
    axes: Float[np.ndarray, "J 3"]
    axes2: Float[np.ndarray, "J 3"]
    points: Float[np.ndarray, "P 3"]
    origins: Float[np.ndarray, "B 3"]


def _rest_program(mech: Mechanism, design) -> tuple:
    geom = geometry(mech, design)
    return geom.anchors, geom.axes, geom.axes2, geom.points


def rest(mech: Mechanism, design=None) -> Rest:
    """The rest geometry of ``design`` (None: the file's) in file units: one compiled
    program per structure (:mod:`linkopt._engine.programs`), where the operations run
    one by one compiled a few dozen small programs per call."""
    padded = design_array(mech, design)
    anchors, axes, axes2, points = programs.call(
        "rest_geometry", mech, _rest_program, padded
    )
    scale = mech.length_scale
    return Rest(
        anchors=np.asarray(anchors) * scale,
        axes=np.asarray(axes),
        axes2=np.asarray(axes2),
        points=np.asarray(points) * scale,
        origins=np.asarray(mech.body_origins, dtype=float),
    )


def metres_per_unit(mech: Mechanism) -> tuple[float, str]:
    """Metres per file unit and the unit's name, from ``[mechanism] units``.

    A file without ``units`` is taken to be in metres (the loader calls the field
    informational, so this is the export's choice, and the files say so).
    """
    units = mech.raw.get("mechanism", {}).get("units")
    if units is None:
        return 1.0, "m (no units given)"
    key = str(units).strip().lower()
    if key not in METRES_PER_UNIT:
        raise MechanismFileError(
            mech.source,
            "mechanism.units",
            f"unknown unit {units!r} for export; expected one of "
            f"{sorted(METRES_PER_UNIT)}",
        )
    return METRES_PER_UNIT[key], key


def body_anchors(mech: Mechanism, rest_pose: Rest, body: int) -> np.ndarray:
    """Distinct rest positions of the joints on ``body`` and its named points, in file
    order, shape ``(k, 3)``; two positions closer than 1e-9 reference lengths are
    one (:func:`linkopt._engine.links.body_places`)."""
    refs = body_places(mech, rest_pose.anchors, rest_pose.points, body)
    if not refs:  # a body with neither joints nor points: its origin
        return rest_pose.origins[body][None]
    return _places(rest_pose)[refs]


def _places(rest_pose: Rest) -> np.ndarray:
    """The anchors followed by the named points, ``(J + P, 3)``: what a place index
    (:mod:`linkopt._engine.links`) points into."""
    return np.concatenate([rest_pose.anchors, rest_pose.points.reshape(-1, 3)])


def body_capsules(
    mech: Mechanism, rest_pose: Rest, body: int, thickness: float | None = None
) -> list[tuple[np.ndarray, np.ndarray, float]]:
    """The link capsules of ``body`` at ``rest_pose``: ``(start, end, radius)`` in file
    units (a sphere where start is end).

    A file with ``[collision]`` gets the capsules it checks
    (:class:`~linkopt._engine.model.Collision`: its segments, radii and layer
    offsets), ``thickness`` (given: the ``--thickness`` of an export) replacing every
    radius; any other file the segments between :func:`body_anchors`
    (:func:`segments`) of diameter ``thickness`` (None: :func:`default_thickness`)."""
    model = mech.collision
    if model is None:
        places = body_anchors(mech, rest_pose, body)
        radius = 0.5 * (thickness or default_thickness(mech))
        if len(places) == 1:
            return [(places[0], places[0], radius)]
        return [(places[a], places[b], radius) for a, b in segments(places)]
    where = _places(rest_pose)
    out = []
    for g in np.flatnonzero(model.segment_bodies == body):
        a, b = model.segment_places[g]
        shift = model.body_offsets[body]
        radius = 0.5 * thickness if thickness else float(model.segment_radii[g])
        out.append((where[a] + shift, where[b] + shift, radius))
    return out


@dataclass(frozen=True)
class Dof:
    """One elementary degree of freedom: ``kind`` hinge | slide | ball, about or along
    ``axis`` (unit, rest frame; zero for a ball)."""

    kind: str
    axis: np.ndarray


@dataclass(frozen=True)
class Edge:
    """A joint as seen from the tree: ``child`` moves relative to ``parent`` through
    ``dofs`` (applied in order, each in the frame the ones before it left)."""

    joint: int
    parent: int
    child: int
    dofs: tuple[Dof, ...]


@dataclass(frozen=True)
class Tree:
    """Spanning tree from the ground: bodies in ``order`` (parents first), the edge
    into each non-ground body, and the loop-closing joints."""

    order: tuple[int, ...]
    edges: dict[int, Edge]
    closures: tuple[int, ...]

    def children(self, body: int) -> list[int]:
        return [
            b for b in self.order if b in self.edges and self.edges[b].parent == body
        ]


def _spherical_frame(axis: np.ndarray, axis2: np.ndarray) -> tuple[np.ndarray, ...]:
    """The Tait–Bryan frame of a spherical joint: its axes if given, else x, y."""
    if np.linalg.norm(axis) == 0 or np.linalg.norm(axis2) == 0:
        axis, axis2 = np.eye(3)[0], np.eye(3)[1]
    return axis, axis2, np.cross(axis, axis2)


def joint_dofs(
    mech: Mechanism, rest_pose: Rest, joint: int, *, reverse: bool, hinges_only: bool
) -> tuple[Dof, ...]:
    """The elementary dofs of ``joint`` moving its second body relative to its first
    (``reverse``: the first relative to the second: dofs in reverse order, axes
    negated).

    revolute → hinge; prismatic → slide; universal → hinge ``axis``, hinge ``axis2``;
    cylindrical → hinge + slide along ``axis``; fixed → none; spherical → ball, or
    with ``hinges_only`` (URDF has no ball) three hinges about the joint's Tait–Bryan
    axes ``axis``, ``axis2``, ``axis × axis2`` (x, y, z when not given).
    """
    n, n2 = rest_pose.axes[joint], rest_pose.axes2[joint]
    kind = mech.joint_types[joint]
    if kind == "spherical":
        if not hinges_only:
            return (Dof("ball", np.zeros(3)),)
        dofs = [Dof("hinge", e) for e in _spherical_frame(n, n2)]
    else:
        dofs = {
            "revolute": [Dof("hinge", n)],
            "prismatic": [Dof("slide", n)],
            "universal": [Dof("hinge", n), Dof("hinge", n2)],
            "cylindrical": [Dof("hinge", n), Dof("slide", n)],
            "fixed": [],
        }[kind]
    if reverse:
        dofs = [Dof(d.kind, -d.axis) for d in reversed(dofs)]
    return tuple(dofs)


def _find(parent: list[int], b: int) -> int:
    while parent[b] != b:
        parent[b] = parent[parent[b]]
        b = parent[b]
    return b


def _tree_joints(mech: Mechanism) -> list[int]:
    """Joints of a spanning forest, Kruskal-style: motor joints first (an actuator needs
    a tree joint), then by :data:`_TREE_PREFERENCE`, file order within a family."""
    motors = set(int(j) for j in mech.motor_joints)
    rank = {kind: k for k, kind in enumerate(_TREE_PREFERENCE)}

    def key(j: int):
        return (j not in motors, rank.get(mech.joint_types[j], len(rank)), j)

    parent = list(range(mech.num_bodies))
    chosen = []
    for j in sorted(range(len(mech.joint_names)), key=key):
        a, b = (_find(parent, int(x)) for x in mech.joint_bodies[j])
        if a != b:
            parent[a] = b
            chosen.append(j)
    return chosen


def spanning_tree(mech: Mechanism, rest_pose: Rest, *, hinges_only=False) -> Tree:
    """The spanning tree from the ground (breadth first over :func:`_tree_joints`).

    Which joints close the loops is a choice the issue leaves open: motor joints are
    kept in the tree so that actuators sit on tree joints, and the families that one
    equality constraint closes best (spherical, then revolute) are left out first.
    The loader has checked that every body is connected to the ground.
    """
    tree_joints = _tree_joints(mech)
    order, edges, frontier = [mech.ground], {}, [mech.ground]
    while frontier:
        body = frontier.pop(0)
        for j in tree_joints:
            i, k = (int(x) for x in mech.joint_bodies[j])
            if body not in (i, k):
                continue
            child = k if i == body else i
            if child == body or child in edges or child == mech.ground:
                continue
            dofs = joint_dofs(
                mech, rest_pose, j, reverse=child == i, hinges_only=hinges_only
            )
            edges[child] = Edge(joint=j, parent=body, child=child, dofs=dofs)
            order.append(child)
            frontier.append(child)
    closures = tuple(j for j in range(len(mech.joint_names)) if j not in tree_joints)
    return Tree(order=tuple(order), edges=edges, closures=closures)


def default_thickness(mech: Mechanism) -> float:
    """The default thickness of link solids (file units):
    :func:`linkopt._engine.links.default_thickness` of the reference length."""
    return links.default_thickness(mech.length_scale)


# ---- joint coordinates of a state -------------------------------------------------


def _hinge_angles(axes: list[np.ndarray], relative: np.ndarray) -> list[float]:
    """Angles ``θ_k`` with ``relative = Π_k Rot(a_k, θ_k)`` for 1-3 mutually
    perpendicular axes (the first two of three, or one of one, are exact for any
    rotation the joint allows; three are the Tait–Bryan angles, |θ2| < π/2)."""
    if len(axes) == 1:
        a = axes[0]
        q = np_from_matrix(relative)
        return [2.0 * np.arctan2(q[1:] @ a, q[0])]
    if len(axes) == 3:
        e = np.stack(axes, axis=1)
        m = e.T @ relative @ e
        return [
            np.arctan2(-m[1, 2], m[2, 2]),
            np.arctan2(m[0, 2], np.hypot(m[0, 0], m[0, 1])),
            np.arctan2(-m[0, 1], m[0, 0]),
        ]
    a1, a2 = axes
    turned = relative @ a2
    first = np.arctan2(a1 @ np.cross(a2, turned), a2 @ turned)
    rest_of = np_axis_angle_matrix(a1, -first) @ relative
    turned = rest_of @ a1
    return [first, np.arctan2(a2 @ np.cross(a1, turned), a1 @ turned)]


def body_poses(mech: Mechanism, state) -> tuple[np.ndarray, np.ndarray]:
    """World origins (file units, ``(B, 3)``) and rotation matrices (``(B, 3, 3)``) of
    a homogenised state."""
    bodies = np.asarray(state, dtype=float).reshape(-1, 7)
    origins = bodies[:, :3] * mech.length_scale
    return origins, np_matrix(bodies[:, 3:])


def edge_values(
    mech: Mechanism, rest_pose: Rest, edge: Edge, origins, rotations
) -> list[np.ndarray]:
    """The coordinates of ``edge``'s dofs in a posed state (file units for slides,
    rad for hinges, a ``wxyz`` quaternion for a ball), one array per dof."""
    p, c = edge.parent, edge.child
    relative = rotations[p].T @ rotations[c]
    if edge.dofs and edge.dofs[0].kind == "ball":
        return [np_from_matrix(relative)]
    hinges = [d.axis for d in edge.dofs if d.kind == "hinge"]
    angles = iter(_hinge_angles(hinges, relative) if hinges else [])
    anchor = rest_pose.anchors[edge.joint]
    on_parent = origins[p] + rotations[p] @ (anchor - rest_pose.origins[p])
    on_child = origins[c] + rotations[c] @ (anchor - rest_pose.origins[c])
    values = []
    for dof in edge.dofs:
        if dof.kind == "hinge":
            values.append(np.array([next(angles)]))
        else:
            values.append(np.array([(on_child - on_parent) @ rotations[p] @ dof.axis]))
    return values
