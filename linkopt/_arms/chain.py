"""One serial chain on the engine: its mechanism definition and its closed-form state.

Every serial-arm family (the module arms of :mod:`~linkopt._arms.codesign`, the DH
tables of :mod:`~linkopt._arms.dh`, the planar arms of :mod:`~linkopt._arms.trace`) is
the same mechanism to the engine: a ground body and one body per joint, joint ``k``
joining body ``k - 1`` to body ``k`` with a motor on it, named points on the bodies and
as many outputs as motors. :func:`chain_definition` writes that mechanism as the plain
dictionary the loader (:func:`linkopt._files.loader.build`) reads; the families differ
only in names, units, body origins and the points and outputs they declare, and pass
those in. :func:`chain_state` is the maximal-coordinate state of a configuration
straight from the frames the bodies carry (a serial chain needs no solve).
"""

from __future__ import annotations

from collections.abc import Sequence

import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from .. import _config  # noqa: F401  (float64 on before any array)
from .._engine import rotations as rot
from .._files.bounds import diameter

#: One named point: ``(name, body index, position at rest (3,))``.
Point = tuple[str, int, Sequence[float]]


def _floats(vector) -> list[float]:
    return [float(v) for v in vector]


def span(points: Float[np.ndarray, "P 3"]) -> float:
    """Diameter of ``points`` as a reference length; 1 when they all coincide (a length
    scale must be positive)."""
    spread = diameter(np.asarray(points))
    return float(spread) if spread > 1e-9 else 1.0


def joint_output(name: str, joint: str, low: float, high: float) -> dict:
    """An output that reads the angle (or travel) of ``joint``."""
    return {"name": name, "joint": joint, "min": low, "max": high}


def coordinate_output(
    name: str, point: str, coordinate: str, low: float, high: float
) -> dict:
    """An output that reads one world coordinate (``"x"``, ``"y"``, ``"z"``) of a named
    point."""
    return {
        "name": name,
        "point": point,
        "coordinate": coordinate,
        "min": low,
        "max": high,
    }


def _header(name: str, ground: str, units: str, reference_length) -> dict:
    head = {"name": name, "ground": ground}
    if units:
        head["units"] = units
    if reference_length is not None:
        head["reference_length"] = float(reference_length)
    return head


def _bodies(names: Sequence[str], origins) -> list[dict]:
    if origins is None:
        return [{"name": b} for b in names]
    return [{"name": b, "origin": _floats(o)} for b, o in zip(names, origins)]


def _joints(bodies, joints, types: str, anchors, axes) -> list[dict]:
    return [
        {
            "name": joint,
            "type": "revolute" if types[k] == "R" else "prismatic",
            "bodies": [bodies[k], bodies[k + 1]],
            "anchor": _floats(anchors[k]),
            "axis": _floats(axes[k]),
        }
        for k, joint in enumerate(joints)
    ]


def chain_definition(
    name: str,
    bodies: Sequence[str],
    joints: Sequence[str],
    motors: Sequence[str],
    anchors: Float[np.ndarray, "n 3"],
    axes: Float[np.ndarray, "n 3"],
    *,
    points: Sequence[Point] = (),
    outputs: Sequence[dict] = (),
    types: str | None = None,
    origins: Float[np.ndarray, "n+1 3"] | None = None,
    units: str = "",
    reference_length: float | None = None,
) -> dict:
    """The mechanism definition of a serial chain, at its rest pose.

    ``bodies`` names the ``n + 1`` bodies, ground first; joint ``k`` (``joints[k]``, of
    type ``types[k]``: ``R`` revolute, ``P`` prismatic; all revolute by default) joins
    ``bodies[k]`` to ``bodies[k + 1]`` at ``anchors[k]`` along ``axes[k]`` and drives
    motor ``motors[k]``. ``points`` are placed on their bodies by index; ``outputs`` are
    written as given (:func:`joint_output`, :func:`coordinate_output`). ``origins``,
    ``units`` and ``reference_length`` are written only when given; otherwise the
    loader's defaults apply.
    """
    types = "R" * len(joints) if types is None else types
    return {
        "mechanism": _header(name, bodies[0], units, reference_length),
        "bodies": _bodies(bodies, origins),
        "joints": _joints(bodies, joints, types, anchors, axes),
        "motors": [{"name": m, "joint": j} for m, j in zip(motors, joints)],
        "points": [
            {"name": p, "body": bodies[b], "position": _floats(x)} for p, b, x in points
        ],
        "outputs": list(outputs),
    }


def _moved(rotation, position, rest_rotation, offset):
    """``(origin, quaternion)`` now of the bodies carrying these frames (any leading
    shape)."""
    q = rot.multiply(rotation, rot.conjugate(rest_rotation))
    x = position if offset is None else position + rot.rotate(q, offset)
    return x, q


def chain_state(
    rotations: Float[Array, "B 4"],
    positions: Float[Array, "B 3"],
    rest_rotations: Float[Array, "B 4"],
    length_scale: float,
    offsets: Float[Array, "B 3"] | None = None,
) -> Float[Array, " 7*B"]:
    """The homogenised engine state (7 per body) of ``B`` chain bodies.

    Each body carries a frame: ``rotations`` / ``positions`` are its world orientation
    (quaternion) and position now, ``rest_rotations`` its orientation at rest. Bodies
    sit at the identity orientation at rest, so body ``b`` moves by ``G_b = F_b
    F_b(rest)⁻¹``: quaternion ``q_b ⊗ q̄_b(rest)``, origin at ``p_b + G_b o_b`` where
    ``offsets`` ``o_b`` is the body origin minus the frame position at rest (``None``:
    every body origin is its frame's position at rest).

    Arrays are handled all bodies at once, lists (or tuples) of per-body rows body by
    body; the two are the same formula and agree to rounding, and each keeps the
    numbers its family had before the families shared this function, bit for bit.
    """
    if not isinstance(rotations, (list, tuple)):
        x, q = _moved(rotations, positions, rest_rotations, offsets)
        return jnp.concatenate([x / length_scale, q], axis=1).ravel()
    bodies = []
    for b in range(len(rotations)):
        offset = None if offsets is None else offsets[b]
        x, q = _moved(rotations[b], positions[b], rest_rotations[b], offset)
        bodies.append(jnp.concatenate([x / length_scale, q]))
    return jnp.concatenate(bodies)
