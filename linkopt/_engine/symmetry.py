"""Symmetries of a mechanism's rest geometry (``[symmetry]``): a mirror plane, or an
n-fold rotation about an axis, optionally with a mirror plane containing the axis.

Design parameters use them to move symmetric copies of a joint by the image of the
same change (:mod:`linkopt._files.design_kinds`); ``[symmetry]`` is read by
:mod:`linkopt._files.symmetry`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from jaxtyping import Float

from .rotations import np_axis_angle_matrix

#: Coincidence tolerance: of anchors, times the reference length; of unit axes.
MIRROR_TOL = 1e-9
#: Largest order of a rotational symmetry (a 1-degree step).
MAX_ORDER = 360


@dataclass(frozen=True)
class Symmetry:
    """A mirror plane (``direction`` its unit normal), or an ``order``-fold rotation
    about the axis through ``point`` along the unit ``direction``, with ``mirror`` the
    unit normal of a mirror plane containing that axis (a dihedral symmetry) or None.

    Its elements other than the identity are numbered ``k = 1 .. size - 1``: the
    rotations by ``360 k / order`` degrees (right-handed about ``direction``), then
    (dihedral) the reflection composed with each rotation.
    """

    direction: Float[np.ndarray, " 3"]
    point: Float[np.ndarray, " 3"]
    kind: str = "mirror"
    order: int = 2
    mirror: Float[np.ndarray, " 3"] | None = None

    @property
    def size(self) -> int:
        """The number of elements, the identity included."""
        if self.kind == "mirror":
            return 2
        return self.order * (1 if self.mirror is None else 2)

    def transform(self, k: int) -> Float[np.ndarray, "3 3"]:
        """The orthogonal map of element ``k``."""
        if self.kind == "mirror":
            return _reflection(self.direction)
        rotation = np_axis_angle_matrix(
            self.direction, 2.0 * np.pi * (k % self.order) / self.order
        )
        return rotation if k < self.order else _reflection(self.mirror) @ rotation

    def image(self, x: Float[np.ndarray, " 3"], k: int) -> Float[np.ndarray, " 3"]:
        """The image of the position ``x`` under element ``k``."""
        return self.point + self.transform(k) @ (x - self.point)

    def words(self, k: int) -> str:
        if self.kind == "mirror" or k == self.order:
            return "mirror image"
        turn = f"the rotation by {360.0 * (k % self.order) / self.order:g} degrees"
        return f"image under {turn}" + (" and the mirror" if k > self.order else "")


def _reflection(n: Float[np.ndarray, " 3"]) -> Float[np.ndarray, "3 3"]:
    return np.eye(3) - 2.0 * np.outer(n, n)
