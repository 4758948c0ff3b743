"""Whether an exported MJCF model can settle onto linkopt's FK.

MuJoCo closes the loops with the equality constraints of :mod:`.mjcf`; they hold the
same conditions as linkopt's passive rows, so the model settles onto FK exactly when
the exported design has as many degrees of freedom at rest as it has motors. A design
whose loops lose that (a loop made redundant and then inconsistent, e.g. a planar
loop whose axes a design tilts out of parallel: it locks) or gain a passive freedom
cannot: the servos either fight the constraints or leave a mode undetermined. The
mobility is ``|s| - rank(∂C_passive/∂s)`` at the rest pose of the design
(:func:`linkopt._engine.mobility.mobility`, here for any design).

Idle spins (rods between two ball joints) are the one freedom linkopt fixes by gauge
rows and MuJoCo does not: a joint's damping stops the spin, but at whatever angle.
The rod's end points and origin (on its axis) settle; a named point off the axis of
such a rod does not, and the file says so.
"""

from __future__ import annotations

import numpy as np

from .._engine.mobility import mobility, mobility_changes
from .._engine.model import Mechanism


def design_mobility(mech: Mechanism, design=None) -> int:
    """Degrees of freedom at the rest pose of ``design`` (None: the file's), idle
    spins not counted (their gauge rows are among the passive rows). The file's own
    design has passed :func:`linkopt._engine.mobility.check_mobility` while loading;
    another one goes through :func:`~linkopt._engine.mobility.mobility_changes`, the
    program that ``verify`` runs on the same design."""
    if design is None or np.array_equal(np.asarray(design), mech.design.p0):
        return mobility(mech)
    (change,) = mobility_changes(mech, np.asarray(design, dtype=np.float64)[None])
    return mech.num_motors if change is None else change.mobility


def _idle_points(mech: Mechanism) -> list[str]:
    """Named points on idly spinning bodies (their spin is free in MuJoCo)."""
    idle = {int(b) for b in mech.idle_bodies}
    return [
        name for name, b in zip(mech.point_names, mech.point_bodies) if int(b) in idle
    ]


def settling_warnings(mech: Mechanism, design=None) -> tuple[str, ...]:
    """One line per reason the MJCF model of ``design`` does not settle onto FK."""
    out = []
    dof = design_mobility(mech, design)
    if dof != mech.num_motors:
        what = "locked" if dof < mech.num_motors else "free to move"
        out.append(
            f"this design has mobility {dof} at rest but {mech.num_motors} motor(s) "
            f"(a redundant loop made inconsistent, or a passive freedom: {what}); "
            "MuJoCo cannot settle it onto linkopt's FK"
        )
    points = _idle_points(mech)
    if points:
        out.append(
            f"point(s) {', '.join(points)} sit on rods that spin idly between two "
            "ball joints; MuJoCo damps the spin but does not fix it, so they need "
            "not settle onto linkopt's FK"
        )
    return tuple(out)
