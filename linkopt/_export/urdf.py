"""URDF export of open-chain mechanisms (serial arms and any loop-free file).

URDF is a tree of links joined by joints whose frames are the child links' frames, and
it cannot hold a loop, so a mechanism with a loop-closing joint is refused (pointing to
MJCF). Link frames: the ground link's frame is the world frame of the file, every other
link's frame sits at the anchor of the joint into it with the identity orientation at
rest (its body's rest orientation), so a joint's ``origin`` is a pure translation and
its ``axis`` is the file's axis. A joint of several dofs (universal: two revolute
joints; cylindrical: revolute + prismatic; spherical: three revolute joints about its
Tait–Bryan axes) gets massless intermediate links named ``<joint>_link<k>``. Every
named point is a link on a fixed joint (the arms' ``tip`` is the tool frame). Lengths
are in metres.

Limits: a motor joint with limits (``[[motors]]`` ``min``/``max``) gets them (a side
the file leaves open: ± the reference length for a slide, ±π for a hinge); else a
revolute joint whose angle is an output gets that output's range as its limits;
other revolute joints are ``continuous``. A prismatic joint without motor limits gets
± the reference length. Effort and velocity (which URDF requires on a limit) are
written as 0, unknown.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

from .._engine.model import Mechanism
from .._engine.welding import part_state, parts
from .._errors import InputError
from .mjcf import dof_names, xml_numbers
from .tree import Rest, body_poses, edge_values, metres_per_unit, rest, spanning_tree


def check_open_chain(mech: Mechanism) -> None:
    """:class:`InputError` (one line, pointing to MJCF) for a mechanism with loops."""
    closures = len(mech.joint_names) - (mech.num_bodies - 1)
    if closures > 0:
        rest_pose = rest(mech)
        names = [mech.joint_names[j] for j in spanning_tree(mech, rest_pose).closures]
        raise InputError(
            f"{mech.source}: URDF cannot hold closed loops ({closures} loop-closing "
            f"joint(s): {', '.join(names)}); export it as MJCF, which holds loops"
        )


def _link_names(mech: Mechanism, joint: int, count: int) -> list[str]:
    """Intermediate links of a joint of ``count`` dofs (``count - 1`` of them)."""
    return [f"{mech.joint_names[joint]}_link{k + 1}" for k in range(count - 1)]


def point_link(mech: Mechanism, point: int) -> str:
    """The link name of a named point (its name, ``_point`` added on a clash)."""
    name = mech.point_names[point]
    return f"{name}_point" if name in mech.body_names else name


def _limits(mech: Mechanism, joint: int) -> tuple[float, float] | None:
    """The range of an angle output read at ``joint`` (rad), if there is one."""
    for k in range(mech.num_outputs):
        if mech.output_joints[k] == joint and mech.output_coords[k] < 0:
            return float(mech.output_min[k]), float(mech.output_max[k])
    return None


def motor_limits(mech: Mechanism, joint: int) -> tuple[float, float] | None:
    """The limits of the motor on ``joint`` (rad or file units; ±inf on a side the
    file leaves open), None without a motor or limits."""
    motors = np.flatnonzero(mech.motor_joints == joint)
    if not mech.motor_limited or not len(motors):
        return None
    m = int(motors[0])
    return float(mech.motor_min[m]), float(mech.motor_max[m])


def _motor_urdf_limits(mech: Mechanism, joint: int, slide: bool, s: float) -> tuple:
    """A limited motor joint's URDF limits (metres or rad): the motor's, a side the
    file leaves open ± the reference length (slide) or ±π (hinge; module docstring)."""
    wide, scale = (mech.length_scale, s) if slide else (np.pi, 1.0)
    low, high = motor_limits(mech, joint)
    return (
        (low if np.isfinite(low) else -wide) * scale,
        (high if np.isfinite(high) else wide) * scale,
    )


def _joint(root, name, kind, parent, child, xyz, axis=None, limits=None) -> None:
    element = ET.SubElement(root, "joint", name=name, type=kind)
    ET.SubElement(element, "parent", link=parent)
    ET.SubElement(element, "child", link=child)
    ET.SubElement(element, "origin", xyz=xml_numbers(xyz), rpy="0 0 0")
    if axis is not None:
        ET.SubElement(element, "axis", xyz=xml_numbers(axis))
    if limits is not None:
        ET.SubElement(
            element,
            "limit",
            lower=xml_numbers(limits[0]),
            upper=xml_numbers(limits[1]),
            effort="0",
            velocity="0",
        )


def link_frames(mech: Mechanism, rest_pose: Rest) -> np.ndarray:
    """Rest world position (file units) of every body's link frame, ``(B, 3)``: the
    world origin for the ground, the anchor of the joint into the body otherwise."""
    tree = spanning_tree(mech, rest_pose, hinges_only=True)
    frames = np.zeros((mech.num_bodies, 3))
    for child, edge in tree.edges.items():
        frames[child] = rest_pose.anchors[edge.joint]
    return frames


def _edge_joints(root, mech, rest_pose, edge, frames, s) -> None:
    parent = mech.body_names[edge.parent]
    names = dof_names(mech, edge.joint, max(len(edge.dofs), 1))
    chain = [parent, *_link_names(mech, edge.joint, len(edge.dofs))]
    chain.append(mech.body_names[edge.child])
    offset = (frames[edge.child] - frames[edge.parent]) * s
    if not edge.dofs:
        _joint(root, names[0], "fixed", parent, chain[-1], offset)
        return
    for k, dof in enumerate(edge.dofs):
        if k + 1 < len(chain) - 1:
            ET.SubElement(root, "link", name=chain[k + 1])
        limits = _limits(mech, edge.joint) if len(edge.dofs) == 1 else None
        if dof.kind == "slide":
            kind, length = "prismatic", mech.length_scale * s
            limits = (-length, length)
        else:
            kind = "continuous" if limits is None else "revolute"
        if len(edge.dofs) == 1 and motor_limits(mech, edge.joint) is not None:
            limits = _motor_urdf_limits(mech, edge.joint, dof.kind == "slide", s)
            kind = "prismatic" if dof.kind == "slide" else "revolute"
        xyz = offset if k == 0 else np.zeros(3)
        _joint(root, names[k], kind, chain[k], chain[k + 1], xyz, dof.axis, limits)


def urdf_text(mech: Mechanism, design=None) -> tuple[str, dict]:
    """The URDF document of ``design`` (None: the file's) and a summary of it; welded
    parts are their own links."""
    mech = parts(mech)
    check_open_chain(mech)
    rest_pose = rest(mech, design)
    tree = spanning_tree(mech, rest_pose, hinges_only=True)
    s, unit = metres_per_unit(mech)
    frames = link_frames(mech, rest_pose)
    root = ET.Element("robot", name=mech.name)
    root.append(
        ET.Comment(
            f" exported by linkopt from {mech.source}; lengths in metres: file units "
            f"{unit} x {s:g}; all joint values zero is the rest pose "
        )
    )
    for body in tree.order:
        ET.SubElement(root, "link", name=mech.body_names[body])
    for body in tree.order[1:]:
        _edge_joints(root, mech, rest_pose, tree.edges[body], frames, s)
    for p in range(len(mech.point_names)):
        body = int(mech.point_bodies[p])
        ET.SubElement(root, "link", name=point_link(mech, p))
        offset = (rest_pose.points[p] - frames[body]) * s
        _joint(
            root,
            f"{point_link(mech, p)}_fixed",
            "fixed",
            mech.body_names[body],
            point_link(mech, p),
            offset,
        )
    ET.indent(root)
    summary = {
        "format": "urdf",
        "links": len(root.findall("link")),
        "joints": len(root.findall("joint")),
        "moving_joints": sum(j.get("type") != "fixed" for j in root.findall("joint")),
        "metres_per_unit": s,
    }
    return ET.tostring(root, encoding="unicode") + "\n", summary


def export_urdf(mech: Mechanism, path, design=None) -> dict:
    """Write the URDF file of ``design`` (file units, None: the file's) to ``path``;
    :class:`InputError` for a mechanism with closed loops. Returns a summary."""
    from .._folders import write_atomic

    text, summary = urdf_text(mech, design)
    write_atomic(Path(path), text)
    return summary


def urdf_joint_values(mech: Mechanism, state, design=None) -> dict[str, float]:
    """URDF joint name → value (rad, metres) of every moving joint for a linkopt state
    (homogenised, of ``design``)."""
    mech, state = parts(mech), part_state(mech, state)
    rest_pose = rest(mech, design)
    tree = spanning_tree(mech, rest_pose, hinges_only=True)
    s, _ = metres_per_unit(mech)
    origins, rotations = body_poses(mech, state)
    values = {}
    for edge in tree.edges.values():
        coords = edge_values(mech, rest_pose, edge, origins, rotations)
        for name, dof, value in zip(
            dof_names(mech, edge.joint, len(edge.dofs)), edge.dofs, coords
        ):
            values[name] = float(value[0]) * (s if dof.kind == "slide" else 1.0)
    return values


def link_poses(mech: Mechanism, state, design=None) -> dict[str, np.ndarray]:
    """World 4x4 transform (metres) of every body link and point link for a linkopt
    state, as the URDF's frames are placed (module docstring)."""
    mech, state = parts(mech), part_state(mech, state)
    rest_pose = rest(mech, design)
    frames = link_frames(mech, rest_pose)
    s, _ = metres_per_unit(mech)
    origins, rotations = body_poses(mech, state)
    poses = {}
    for b in range(mech.num_bodies):
        at = origins[b] + rotations[b] @ (frames[b] - rest_pose.origins[b])
        poses[mech.body_names[b]] = _pose(rotations[b], at * s)
    for p in range(len(mech.point_names)):
        b = int(mech.point_bodies[p])
        at = origins[b] + rotations[b] @ (rest_pose.points[p] - rest_pose.origins[b])
        poses[point_link(mech, p)] = _pose(rotations[b], at * s)
    return poses


def _pose(rotation: np.ndarray, position: np.ndarray) -> np.ndarray:
    pose = np.eye(4)
    pose[:3, :3], pose[:3, 3] = rotation, position
    return pose
