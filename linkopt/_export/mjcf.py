"""MuJoCo MJCF export of any mechanism, closed loops included.

The bodies form the spanning tree of :func:`linkopt._export.tree.spanning_tree`, nested
from the ground (a static body of the world), each at its rest origin with the identity
orientation, so MuJoCo's reference configuration ``qpos0`` is the rest pose of the
exported design. Tree joints become MuJoCo joints in the child body (hinge, slide,
ball; a universal joint is two hinges and a cylindrical one a hinge and a slide in the
same body, which MuJoCo composes in order, so no intermediate body is needed; a fixed
joint welds the child). Each loop-closing joint becomes equality constraints between
its two bodies:

* spherical: one ``connect`` at the anchor;
* revolute: a ``connect`` at the anchor and one at ``anchor + L n`` (``L`` half the
  reference length), so the two bodies share the axis (6 rows for 5 conditions;
  MuJoCo's soft constraints take the redundant row);
* fixed: a ``weld``;
* universal, prismatic, cylindrical (and a motor joint that has to close a loop): a
  small closure body, child of the joint's first body, carries the joint's dofs and is
  welded to the second body. One equality family that MuJoCo has cannot hold the
  universal joint's ``n · n2 = 0`` by itself; the closure body is the cross of the
  joint.

Motors are ``position`` actuators on their joints (gains from the exported masses, a
5 Hz critically damped servo behind a 50 ms command filter; a motor's limits are
its actuator's ``ctrlrange`` and its joint's ``range``, both ``limited``), named
points are sites, the links are capsules between the joint anchors, and every
length is in metres (the scale is written in a comment). Gravity is zero: a
mechanism file does not say which way is down.

Dynamics: driven from rest to motor values, the model settles onto
linkopt's FK. Every joint has damping and armature, and the equalities' ``solref``
and ``solimp``, the time step and the solver's tolerance are set, all scaled to the
mechanism's reference inertia and length (the constants below say why each value).
A design that cannot settle (:mod:`.settling`) gets a warning comment in the file and
in the summary.
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

from .._engine.model import Mechanism
from .._engine.welding import part_state, parts
from .settling import settling_warnings
from .tree import (
    Edge,
    Rest,
    Tree,
    body_capsules,
    body_poses,
    default_thickness,
    edge_values,
    joint_dofs,
    metres_per_unit,
    rest,
    spanning_tree,
)

#: Density of the link solids (kg/m³, MuJoCo's default: water). With the exported
#: solids' total mass ``M`` and the reference length ``L`` (m) it gives the
#: reference inertia ``I = M L²`` every gain below is scaled by, so the dynamics are
#: the same for a mechanism drawn in mm or in m, light or heavy (none of this changes
#: the kinematics: at the FK solution no force acts, gravity being zero).
DENSITY = 1000.0
#: The servo's natural frequency (Hz): ``kp = I ω²`` (``M ω²`` for a linear motor),
#: ``kv = 2 √(kp I)`` (critically damped for the reference inertia).
SERVO_HZ = 5.0
#: Time constant (s) of the first-order filter between a motor's control and its
#: servo (MuJoCo's ``timeconst``): a step command reaches the joint as a ramp, so the
#: passive bodies get no impulse.
SETPOINT_TIME = 0.05
#: Every joint's damping as a damping ratio of the reference inertia at the servo's
#: frequency (``2 ζ ω I``; ``2 ζ ω M`` for slides). Passive modes the servos do not
#: reach (an idle rod's spin, a mode near a singularity) die out with it; larger values
#: slow every motion.
JOINT_DAMPING = 0.03
#: Every joint's armature (rotor inertia) as a fraction of the reference inertia (of
#: ``M`` for slides). It keeps light links (a finger's rods, 0.1 % of the reference
#: inertia) from being flung onto another assembly branch by the constraint forces.
ARMATURE = 0.01
#: Time step (s): small enough that light rods settle (MuJoCo's default 2 ms does not
#: settle every shipped mechanism; ``tests/test_export_mjcf.py`` checks they settle).
TIMESTEP = 5e-4
#: The loop-closing equalities: ``solref`` time constant (s), critically damped:
#: 4 time steps (MuJoCo asks for at least 2), ten times stiffer than MuJoCo's default
#: 20 ms; ``solimp`` impedance from 0.95 to 0.99 over a width of 1e-3 reference
#: lengths (MuJoCo's default width is 1 mm whatever the size, and its 0.9-0.95 leaves
#: the loops visibly open).
EQUALITY_TIME = 2e-3
EQUALITY_IMPEDANCE = (0.95, 0.99)
EQUALITY_WIDTH = 1e-3
#: The constraint solver: Newton (MuJoCo's default), up to 100 iterations, to a
#: tolerance of 1e-10 (default 1e-8) so the equalities close to ~1e-12 of the size.
ITERATIONS = 100
TOLERANCE = 1e-10
_MJ_KIND = {"hinge": "hinge", "slide": "slide", "ball": "ball"}


def _short(v: float) -> str:
    """The shortest text that reads back as ``v`` exactly (``repr``), ``0`` for 0."""
    text = repr(v + 0.0)
    return text[:-2] if text.endswith(".0") else text


def xml_numbers(values) -> str:
    return " ".join(_short(float(v)) for v in np.atleast_1d(values))


def dof_names(mech: Mechanism, joint: int, count: int) -> list[str]:
    """MJCF joint names of a linkopt joint's dofs: its name, or ``name_1``, ``name_2``
    … for a joint of several dofs."""
    name = mech.joint_names[joint]
    return [name] if count == 1 else [f"{name}_{k + 1}" for k in range(count)]


def closure_kind(mech: Mechanism, joint: int) -> str:
    """How a loop-closing joint is written: connect, axis (two connects), weld, or
    body (a closure body welded to the second body; module docstring)."""
    if int(joint) in {int(j) for j in mech.motor_joints}:
        return "body"
    return {"spherical": "connect", "revolute": "axis", "fixed": "weld"}.get(
        mech.joint_types[joint], "body"
    )


def _solid_mass(start, end, radius: float) -> float:
    """Mass (kg) of a capsule from ``start`` to ``end`` (m) of ``radius`` (m)."""
    length = float(np.linalg.norm(np.asarray(end) - np.asarray(start)))
    return DENSITY * math.pi * radius**2 * (length + 4.0 / 3.0 * radius)


def exported_mass(mech: Mechanism, rest_pose: Rest, tree: Tree, thickness, s) -> float:
    """Total mass (kg) of the solids the export writes: every body's capsules and
    spheres, and the sphere of each closure body."""
    mass = 0.0
    for body in range(mech.num_bodies):
        if body == mech.ground:
            continue
        for start, end, radius in body_capsules(mech, rest_pose, body, thickness):
            mass += _solid_mass(start * s, end * s, radius * s)
    closure_radius = 0.5 * (thickness or default_thickness(mech)) * s
    bodies = sum(closure_kind(mech, j) == "body" for j in tree.closures)
    return max(mass + bodies * _solid_mass(0.0, 0.0, closure_radius), 1e-12)


class _Writer:
    """Builds the MJCF element tree of one design (lengths scaled by ``s``)."""

    def __init__(self, mech: Mechanism, design, thickness: float | None):
        self.mech = mech
        self.rest: Rest = rest(mech, design)
        self.tree: Tree = spanning_tree(mech, self.rest)
        self.s, self.unit = metres_per_unit(mech)
        self.thickness = thickness
        self.radius = 0.5 * (thickness or default_thickness(mech)) * self.s
        self.mass = exported_mass(mech, self.rest, self.tree, thickness, self.s)
        self.size = mech.length_scale * self.s  # the reference length, m
        self.inertia = self.mass * self.size**2  # kg m², the reference inertia

    def local(self, body: int, world) -> str:
        return xml_numbers((np.asarray(world) - self.rest.origins[body]) * self.s)

    def add_geoms(self, element, body: int) -> None:
        """The body's link capsules (:func:`~.tree.body_capsules`), a sphere where a
        capsule has no length."""
        for start, end, radius in body_capsules(
            self.mech, self.rest, body, self.thickness
        ):
            size = xml_numbers(radius * self.s)
            if np.array_equal(start, end):
                at = self.local(body, start)
                ET.SubElement(element, "geom", type="sphere", size=size, pos=at)
                continue
            ends = self.local(body, start) + " " + self.local(body, end)
            ET.SubElement(element, "geom", type="capsule", size=size, fromto=ends)

    def add_sites(self, element, body: int) -> None:
        for p in np.flatnonzero(self.mech.point_bodies == body):
            ET.SubElement(
                element,
                "site",
                name=self.mech.point_names[p],
                pos=self.local(body, self.rest.points[p]),
                size=xml_numbers(0.6 * self.radius),
            )

    def add_dofs(self, element, body: int, joint: int, dofs, at) -> None:
        for name, dof in zip(dof_names(self.mech, joint, len(dofs)), dofs):
            attributes = {"name": name, "type": _MJ_KIND[dof.kind], "pos": at}
            attributes |= self.dof_dynamics(dof.kind)
            if dof.kind != "ball":
                attributes["axis"] = xml_numbers(dof.axis)
            limits = motor_range(self.mech, joint, self.s)
            if limits is not None:
                attributes |= {"limited": "true", "range": limits}
            ET.SubElement(element, "joint", attributes)

    def dof_dynamics(self, kind: str) -> dict[str, str]:
        inertia = self.inertia if kind != "slide" else self.mass
        omega = 2.0 * math.pi * SERVO_HZ
        return {
            "damping": xml_numbers(JOINT_DAMPING * 2.0 * omega * inertia),
            "armature": xml_numbers(ARMATURE * inertia),
        }

    def add_body(self, parent_element, body: int) -> None:
        mech, rest_pose = self.mech, self.rest
        edge = self.tree.edges.get(body)
        origin = rest_pose.origins[body]
        offset = origin - (rest_pose.origins[edge.parent] if edge else 0.0)
        element = ET.SubElement(
            parent_element,
            "body",
            name=mech.body_names[body],
            pos=xml_numbers(offset * self.s),
        )
        if edge is not None:
            at = self.local(body, rest_pose.anchors[edge.joint])
            self.add_dofs(element, body, edge.joint, edge.dofs, at)
        self.add_geoms(element, body)
        self.add_sites(element, body)
        for j in self.tree.closures:
            if closure_kind(mech, j) == "body" and mech.joint_bodies[j, 0] == body:
                self.add_closure_body(element, body, j)
        for child in self.tree.children(body):
            self.add_body(element, child)

    def add_closure_body(self, element, body: int, joint: int) -> None:
        anchor = self.rest.anchors[joint]
        cross = ET.SubElement(
            element,
            "body",
            name=closure_body_name(self.mech, joint),
            pos=self.local(body, anchor),
        )
        dofs = joint_dofs(self.mech, self.rest, joint, reverse=False, hinges_only=False)
        self.add_dofs(cross, body, joint, dofs, xml_numbers(np.zeros(3)))
        ET.SubElement(cross, "geom", type="sphere", size=xml_numbers(self.radius))


def closure_body_name(mech: Mechanism, joint: int) -> str:
    """Name of the closure body of a loop-closing joint (module docstring)."""
    name = f"{mech.joint_names[joint]}_closure"
    while name in mech.body_names:
        name += "_"
    return name


def _equalities(w: _Writer, root) -> int:
    mech, rest_pose = w.mech, w.rest
    equality = ET.SubElement(root, "equality")
    rows = 0
    for j in w.tree.closures:
        i, k = (mech.body_names[int(b)] for b in mech.joint_bodies[j])
        name, kind = mech.joint_names[j], closure_kind(mech, j)
        first = int(mech.joint_bodies[j, 0])
        anchor = rest_pose.anchors[j]
        if kind in ("connect", "axis"):
            ET.SubElement(
                equality,
                "connect",
                name=name,
                body1=i,
                body2=k,
                anchor=w.local(first, anchor),
            )
            rows += 3
        if kind == "axis":
            tip = anchor + 0.5 * mech.length_scale * rest_pose.axes[j]
            ET.SubElement(
                equality,
                "connect",
                name=f"{name}_axis",
                body1=i,
                body2=k,
                anchor=w.local(first, tip),
            )
            rows += 3
        if kind in ("weld", "body"):
            body1 = i if kind == "weld" else closure_body_name(mech, j)
            ET.SubElement(equality, "weld", name=name, body1=body1, body2=k)
            rows += 6
    if not len(equality):
        root.remove(equality)
    return rows


def _actuators(w: _Writer, root) -> None:
    mech = w.mech
    if not mech.num_motors:
        return
    omega = 2.0 * math.pi * SERVO_HZ
    actuator = ET.SubElement(root, "actuator")
    for m, joint in enumerate(mech.motor_joints):
        carrier = w.mass if mech.motor_linear[m] else w.inertia
        kp = carrier * omega * omega
        ET.SubElement(
            actuator,
            "position",
            name=mech.motor_names[m],
            joint=mech.joint_names[int(joint)],
            kp=xml_numbers(kp),
            kv=xml_numbers(2.0 * math.sqrt(kp * carrier)),
            **_ctrl_range(mech, int(joint), w.s),
            timeconst=xml_numbers(SETPOINT_TIME),
        )


def motor_range(mech: Mechanism, joint: int, s: float) -> str | None:
    """The limits of the motor on ``joint`` as MJCF writes a range (rad, or metres
    for a linear motor: ``s`` metres per file unit; ``inf`` on a side without one),
    None when the joint has no motor or the file no limits. A motor joint's
    coordinate is its motor value (:func:`joint_values`)."""
    motors = np.flatnonzero(mech.motor_joints == joint)
    if not mech.motor_limited or not len(motors):
        return None
    m = int(motors[0])
    scale = s if mech.motor_linear[m] else 1.0
    return xml_numbers([mech.motor_min[m] * scale, mech.motor_max[m] * scale])


def _ctrl_range(mech: Mechanism, joint: int, s: float) -> dict:
    """The ``ctrllimited``/``ctrlrange`` of a position actuator on ``joint`` (its
    motor's limits), none without them."""
    limits = motor_range(mech, joint, s)
    return {} if limits is None else {"ctrllimited": "true", "ctrlrange": limits}


def mjcf_text(
    mech: Mechanism, design=None, *, thickness: float | None = None
) -> tuple[str, dict]:
    """The MJCF document of ``design`` (None: the file's) and a summary of it; welded
    parts are their own bodies (:func:`~linkopt._engine.welding.parts`)."""
    mech = parts(mech)
    w = _Writer(mech, design, thickness)
    solref = xml_numbers([EQUALITY_TIME, 1.0])
    solimp = xml_numbers([*EQUALITY_IMPEDANCE, EQUALITY_WIDTH * w.size])
    root = ET.Element("mujoco", model=mech.name)
    root.append(
        ET.Comment(
            f" exported by linkopt from {mech.source}; lengths in metres: file units "
            f"{w.unit} x {w.s:g}; qpos0 is the rest pose of the exported design "
        )
    )
    warnings = settling_warnings(mech, design)
    for line in warnings:
        root.append(ET.Comment(f" warning: {line} "))
    ET.SubElement(root, "compiler", angle="radian", autolimits="true")
    ET.SubElement(
        root,
        "option",
        gravity="0 0 0",
        integrator="implicitfast",
        timestep=xml_numbers(TIMESTEP),
        solver="Newton",
        iterations=str(ITERATIONS),
        tolerance=xml_numbers(TOLERANCE),
    )
    default = ET.SubElement(root, "default")
    ET.SubElement(default, "equality", solref=solref, solimp=solimp)
    ET.SubElement(
        default, "geom", contype="0", conaffinity="0", density=xml_numbers(DENSITY)
    )
    worldbody = ET.SubElement(root, "worldbody")
    w.add_body(worldbody, mech.ground)
    rows = _equalities(w, root)
    _actuators(w, root)
    ET.indent(root)
    summary = {
        "format": "mjcf",
        "bodies": mech.num_bodies,
        "closures": [mech.joint_names[j] for j in w.tree.closures],
        "equality_rows": rows,
        "actuators": mech.num_motors,
        "sites": len(mech.point_names),
        "metres_per_unit": w.s,
        "warnings": list(warnings),
    }
    return ET.tostring(root, encoding="unicode") + "\n", summary


def export_mjcf(
    mech: Mechanism, path, design=None, *, thickness: float | None = None
) -> dict:
    """Write the MJCF file of ``design`` (file units, None: the file's) to ``path``.

    Returns a summary (bodies, loop-closing joints, equality rows, actuators, sites,
    metres per file unit, warnings of :mod:`.settling`). ``thickness`` is the capsule
    diameter in file units (default :func:`linkopt._export.tree.default_thickness`).
    """
    from .._folders import write_atomic

    text, summary = mjcf_text(mech, design, thickness=thickness)
    write_atomic(Path(path), text)
    return summary


def joint_values(mech: Mechanism, state, design=None) -> dict[str, np.ndarray]:
    """``qpos`` entries of every MJCF joint for a linkopt state (homogenised, of
    ``design``): MJCF joint name → its coordinates (rad; metres for slides; a ``wxyz``
    quaternion for a ball). With these, MuJoCo's kinematics puts every body where the
    state has it and the equality constraints hold to the state's residual."""
    mech, state = parts(mech), part_state(mech, state)
    rest_pose = rest(mech, design)
    tree = spanning_tree(mech, rest_pose)
    s, _ = metres_per_unit(mech)
    origins, rotations = body_poses(mech, state)
    edges = list(tree.edges.values())
    for j in tree.closures:
        if closure_kind(mech, j) == "body":
            i, k = (int(b) for b in mech.joint_bodies[j])
            dofs = joint_dofs(mech, rest_pose, j, reverse=False, hinges_only=False)
            edges.append(Edge(joint=j, parent=i, child=k, dofs=dofs))
    values: dict[str, np.ndarray] = {}
    for edge in edges:
        coords = edge_values(mech, rest_pose, edge, origins, rotations)
        names = dof_names(mech, edge.joint, len(edge.dofs))
        for name, dof, value in zip(names, edge.dofs, coords):
            values[name] = value * s if dof.kind == "slide" else value
    return values
