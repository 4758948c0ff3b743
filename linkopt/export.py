"""Designs out of linkopt, one function per format: MuJoCo MJCF and URDF (the
kinematic formats), STL and GLB (the solids), DXF and SVG (sheet drawings of a planar
mechanism's links).

This namespace is the only home of its names. Until the next release the old
top-level names still work, with a ``DeprecationWarning`` naming the name here
(``linkopt.export_mjcf``, ``linkopt.export_urdf``, ...).
"""

from typing import TYPE_CHECKING

from ._namespace import namespace as _namespace

#: each name here -> (its module under :mod:`linkopt`, its name there)
_NAMES = {
    "mjcf": ("_export.mjcf", "export_mjcf"),
    "urdf": ("_export.urdf", "export_urdf"),
    "stl": ("_export.meshes", "export_stl"),
    "glb": ("_export.meshes", "export_glb"),
    "dxf": ("_export.sheet", "export_dxf"),
    "svg": ("_export.sheet", "export_svg"),
}

__getattr__, __dir__ = _namespace(__name__, _NAMES)

if TYPE_CHECKING:  # the eager imports, for type checkers and editors
    from ._export.meshes import export_glb as glb
    from ._export.meshes import export_stl as stl
    from ._export.mjcf import export_mjcf as mjcf
    from ._export.sheet import export_dxf as dxf
    from ._export.sheet import export_svg as svg
    from ._export.urdf import export_urdf as urdf

__all__ = sorted(_NAMES)
