"""STL and GLB solids of a mechanism at the rest pose of one design (trimesh).

Each body is one watertight mesh: capsules of diameter ``thickness`` along the segments
between its joint anchors and named points (:func:`linkopt._export.tree.body_capsules`,
the capsules ``[collision]`` checks) and a sphere of diameter 1.5 ``thickness`` at each
of its joints, merged into one solid by a boolean union (manifold3d). STL has no
units: its files are in the mechanism's file units (what CAD and slicers take for a mm
file). GLB is in metres, glTF's unit, one scene with one node per body, named like the
body, whose transform places the body's frame (its rest origin) and whose mesh is in
that frame.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from .._engine.model import Mechanism
from .._engine.welding import parts
from .._errors import InputError
from .._folders import write_atomic
from .tree import Rest, body_capsules, default_thickness, metres_per_unit, rest

if TYPE_CHECKING:  # trimesh is imported where a solid is made: importing it takes
    # about a second, which the figures that only need this module's constants
    # (:mod:`linkopt._draw.planar` via :mod:`.sheet`) should not pay
    import trimesh

#: Joint spheres are this much thicker than the links.
JOINT_FACTOR = 1.5


def _capsule(a: np.ndarray, b: np.ndarray, radius: float) -> trimesh.Trimesh:
    import trimesh

    d = b - a
    length = float(np.linalg.norm(d))
    transform = trimesh.geometry.align_vectors([0.0, 0.0, 1.0], d / length)
    transform[:3, 3] = 0.5 * (a + b)
    return trimesh.creation.capsule(height=length, radius=radius, transform=transform)


def _sphere(at: np.ndarray, radius: float) -> trimesh.Trimesh:
    import trimesh

    sphere = trimesh.creation.icosphere(subdivisions=2, radius=radius)
    sphere.apply_translation(at)
    return sphere


def body_mesh(
    mech: Mechanism, rest_pose: Rest, body: int, thickness: float | None
) -> trimesh.Trimesh:
    """The watertight solid of ``body`` in world coordinates at rest (file units):
    its link capsules (:func:`~.tree.body_capsules`; a file with ``[collision]`` gets
    the ones it checks, in the body's layer) and its joint spheres."""
    capsules = body_capsules(mech, rest_pose, body, thickness)
    parts = [_capsule(a, b, r) for a, b, r in capsules if np.any(a != b)]
    model = mech.collision
    shift = np.zeros(3) if model is None else model.body_offsets[body]
    radius = 0.5 * thickness if thickness else float(model.body_radii[body])
    on_body = mech.joints_on(body)
    parts += [
        _sphere(rest_pose.anchors[j] + shift, JOINT_FACTOR * radius) for j in on_body
    ]
    if not parts:  # one place and no joint: a sphere there
        parts = [_sphere(capsules[0][0], capsules[0][2])]
    _require_manifold()
    import trimesh

    solid = (
        parts[0] if len(parts) == 1 else trimesh.boolean.union(parts, engine="manifold")
    )
    solid.metadata["name"] = mech.body_names[body]
    return solid


def _require_manifold() -> None:
    """:class:`InputError` when the boolean engine (the ``export`` extra) is
    missing."""
    try:
        import manifold3d  # noqa: F401
    except ImportError:
        raise InputError(
            "STL/GLB export needs manifold3d to merge each body into one solid: "
            "pip install -e '.[export]'"
        ) from None


def check_thickness(mech: Mechanism, thickness) -> float:
    """``thickness`` (file units; None: the default) if it is a positive finite number
    at most the reference length, else :class:`InputError`."""
    if thickness is None:
        return default_thickness(mech)
    value = float(thickness)
    if not np.isfinite(value) or value <= 0 or value > mech.length_scale:
        raise InputError(
            f"--thickness: {thickness!r}: expected a positive number of file units at "
            f"most the reference length ({mech.length_scale:g})"
        )
    return value


def body_meshes(mech: Mechanism, design=None, thickness=None) -> list[trimesh.Trimesh]:
    """One watertight solid per body (file order), world coordinates at the rest pose
    of ``design``, file units; ``thickness`` None: the file's ``[collision]`` radii,
    or the default thickness; a welded part is its own solid."""
    mech = parts(mech)
    if thickness is not None or mech.collision is None:
        thickness = check_thickness(mech, thickness)
    rest_pose = rest(mech, design)
    return [body_mesh(mech, rest_pose, b, thickness) for b in range(mech.num_bodies)]


def _summary(kind: str, meshes, s: float, files: list[str]) -> dict:
    return {
        "format": kind,
        "bodies": len(meshes),
        "watertight": all(m.is_watertight for m in meshes),
        "triangles": int(sum(len(m.faces) for m in meshes)),
        "metres_per_unit": s,
        "files": files,
    }


def export_stl(mech: Mechanism, path, design=None, *, thickness=None) -> dict:
    """STL solids of ``design`` in file units: ``path`` is a folder that gets one
    ``<body>.stl`` per body (one part per print). One file for all bodies is not
    offered: neighbouring bodies' joint spheres coincide, so the shells would share
    vertices and the file would not be watertight."""
    meshes = body_meshes(mech, design, thickness)
    s, _ = metres_per_unit(mech)
    path = Path(path)
    path.mkdir(parents=True, exist_ok=True)
    files = []
    for name, mesh in zip(mech.body_names, meshes):
        target = path / f"{name}.stl"
        write_atomic(target, mesh.export(file_type="stl"))
        files.append(str(target))
    return _summary("stl", meshes, s, files)


def scene(mech: Mechanism, design=None, *, thickness=None) -> trimesh.Scene:
    """The GLB scene: one node per body, named like it, in metres (module
    docstring)."""
    meshes = body_meshes(mech, design, thickness)
    s, _ = metres_per_unit(mech)
    import trimesh

    world = trimesh.Scene()
    for b, (name, mesh) in enumerate(zip(mech.body_names, meshes)):
        origin = mech.body_origins[b] * s
        local = mesh.copy()
        local.apply_scale(s)
        local.apply_translation(-origin)
        transform = np.eye(4)
        transform[:3, 3] = origin
        world.add_geometry(local, node_name=name, geom_name=name, transform=transform)
    return world


def export_glb(mech: Mechanism, path, design=None, *, thickness=None) -> dict:
    """Write the GLB scene of ``design`` to ``path`` (metres); returns a summary."""
    world = scene(mech, design, thickness=thickness)
    write_atomic(Path(path), world.export(file_type="glb"))
    s, _ = metres_per_unit(mech)
    return _summary("glb", list(world.geometry.values()), s, [str(path)])
