"""Designs out of linkopt: MuJoCo MJCF, URDF, STL and GLB files.

:mod:`.tree` holds what the formats share: the rest geometry of one design in file
units, the unit scale, the spanning tree of the bodies from the ground and the joint
coordinates of a linkopt state in that tree. :mod:`.mjcf` and :mod:`.urdf` write the
kinematic formats, :mod:`.meshes` the solid ones (STL, GLB).
"""
