"""Designs out of linkopt, one function per format: MuJoCo MJCF and URDF (the
kinematic formats), STL and GLB (the solids), DXF and SVG (sheet drawings of a planar
mechanism's links).

Each name is also a top-level name of :mod:`linkopt`, the same object: ``mjcf`` is
``linkopt.export_mjcf``, ``urdf`` ``linkopt.export_urdf``, ``stl``
``linkopt.export_stl``, ``glb`` ``linkopt.export_glb``, ``dxf``
``linkopt.export_dxf`` and ``svg`` ``linkopt.export_svg``.
"""

from typing import TYPE_CHECKING

from ._namespace import namespace as _namespace

#: each name here -> its top-level name in :mod:`linkopt`
_TOP_LEVEL = {
    "mjcf": "export_mjcf",
    "urdf": "export_urdf",
    "stl": "export_stl",
    "glb": "export_glb",
    "dxf": "export_dxf",
    "svg": "export_svg",
}

__getattr__, __dir__ = _namespace(__name__, _TOP_LEVEL)

if TYPE_CHECKING:  # the eager imports, for type checkers and editors
    from ._export.meshes import export_glb as glb
    from ._export.meshes import export_stl as stl
    from ._export.mjcf import export_mjcf as mjcf
    from ._export.sheet import export_dxf as dxf
    from ._export.sheet import export_svg as svg
    from ._export.urdf import export_urdf as urdf

__all__ = sorted(_TOP_LEVEL)
