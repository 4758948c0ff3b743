"""Whether a mechanism is planar, and its plane: the one test behind every figure
(:mod:`.plots`' mechanism figure and :mod:`.animation`'s GIFs).

A mechanism is planar when its rest joint anchors and named points lie in one plane
(to ``PLANAR_TOLERANCE`` of its reference length) and its joints keep every body's
motion in that plane: rotary axes (revolute, cylindrical, universal) along the plane's
normal, prismatic axes in the plane (a slider slides in the plane). Spherical and
fixed joints have no axis to check. When the anchors lie on a line (or at one point),
the first rotary axis, or failing one the normal to the first prismatic axis and the
line, chooses the plane.
"""

from __future__ import annotations

import numpy as np
from jaxtyping import Float

from .._engine.geometry import design_vector, geometry
from .._engine.model import AXIAL_JOINTS, Mechanism
from .._export.sheet import basis

#: Out-of-plane spread of the anchors and axes, relative to the reference length, below
#: which a mechanism is planar.
PLANAR_TOLERANCE = 1e-9


def _axes(mech: Mechanism, geom) -> tuple[np.ndarray, np.ndarray]:
    """The rest axes of the rotary and of the prismatic joints, ``(R, 3)`` and
    ``(S, 3)``."""
    axes = np.asarray(geom.axes)
    types = mech.joint_types
    rotary = [t in AXIAL_JOINTS and t != "prismatic" for t in types]
    sliding = [t == "prismatic" for t in types]
    return axes[rotary], axes[sliding]


def _candidate(
    centred: np.ndarray, rotary: np.ndarray, sliding: np.ndarray, tol: float
) -> np.ndarray | None:
    """The only plane normal the members and axes allow to be tested."""
    _, sigma, vt = np.linalg.svd(centred, full_matrices=True)
    if len(sigma) >= 2 and sigma[1] > tol:
        return vt[2]
    if len(rotary):
        return rotary[0]
    if len(sigma) and sigma[0] > tol and len(sliding):
        normal = np.cross(vt[0], sliding[0])
        size = np.linalg.norm(normal)
        return normal / size if size > 1e-9 else None
    return None


def plane_normal(mech: Mechanism, design=None) -> Float[np.ndarray, " 3"] | None:
    """The unit normal of a planar mechanism's plane at rest with ``design`` (None: the
    file's), or None for a spatial one (module docstring)."""
    geom = geometry(mech, design_vector(mech, design))
    members = np.concatenate([np.asarray(geom.anchors), np.asarray(geom.points)])
    centred = members - members.mean(axis=0)
    rotary, sliding = _axes(mech, geom)
    tol = PLANAR_TOLERANCE  # homogenised: relative to the reference length
    normal = _candidate(centred, rotary, sliding, tol)
    if normal is None or np.max(np.abs(centred @ normal), initial=0.0) > tol:
        return None
    if len(rotary) and np.max(np.linalg.norm(np.cross(rotary, normal), axis=1)) > 1e-9:
        return None
    if len(sliding) and np.max(np.abs(sliding @ normal)) > 1e-9:
        return None
    return normal


def plane_basis(mech: Mechanism, design=None) -> Float[np.ndarray, "2 3"] | None:
    """``(2, 3)`` orthonormal in-plane axes of a planar mechanism, world axes where the
    plane is a coordinate plane; None for a spatial one."""
    normal = plane_normal(mech, design)
    return None if normal is None else basis(normal)
