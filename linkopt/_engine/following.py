"""Named points at the rest pose of a design: the traceable half of
:mod:`.attachment`, whose rule (fixed at load, numpy) says how each point follows its
body's anchors; here the anchors of a design move the points by that rule, and the
point parameters (``kind = "point"``, :func:`drive`) set the coordinates they name."""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from .. import _config  # noqa: F401  (float64 on before any array)
from .attachment import LINE, PLANE, Attachment
from .rotations import turn_onto, unit


def follow(
    attachment: Attachment,
    positions0: Float[np.ndarray, "P 3"],
    anchors0: Float[np.ndarray, "J 3"],
    anchors: Float[Array, "J 3"],
) -> Float[Array, "P 3"]:
    """Rest positions of the points for the design whose anchors are ``anchors``
    (file units), traceable in ``anchors``; ``positions0`` and ``anchors0`` are those
    of the initial design. Written as the initial positions plus what the design
    changes, so the initial design gives ``positions0`` (to rounding in the turned
    offsets, about 1e-16 of their length). numpy where ``anchors`` is a numpy array
    (a concrete mechanism: :mod:`.point_moves` tries many designs without tracing),
    JAX otherwise."""
    xp = np if isinstance(anchors, np.ndarray) else jnp
    moved = xp.asarray(attachment.weights) @ (anchors - xp.asarray(anchors0))
    points = xp.asarray(positions0) + moved
    for hull, turn in ((LINE, _line), (PLANE, _plane)):
        index = np.flatnonzero(attachment.hulls == hull)
        if len(index):
            spans, offsets = attachment.spans[index], attachment.offsets[index]
            change = turn(xp, spans, offsets, anchors0, anchors) - turn(
                xp, spans, offsets, anchors0, xp.asarray(anchors0)
            )
            if xp is np:
                points[index] += change
            else:
                points = points.at[index].add(change)
    return points


def _directions(xp, spans: np.ndarray, anchors) -> Float[Array, "N 2 3"]:
    return xp.einsum("nkj,jc->nkc", xp.asarray(spans), anchors)


def _line(xp, spans, offsets, anchors0, anchors):
    """The offsets turned by the smallest rotation taking the line's direction at the
    initial design to its direction at this one (Rodrigues)."""
    u = unit(xp, _directions(xp, spans, xp.asarray(anchors0))[:, 0])
    v = unit(xp, _directions(xp, spans, anchors)[:, 0])
    return turn_onto(xp, u, v, xp.asarray(offsets))


def _plane(xp, spans, offsets, anchors0, anchors):
    """The offsets (along the plane's normal) along the normal at this design."""
    e0 = _directions(xp, spans, xp.asarray(anchors0))
    e = _directions(xp, spans, anchors)
    n0 = unit(xp, xp.cross(e0[:, 0], e0[:, 1]))
    n = unit(xp, xp.cross(e[:, 0], e[:, 1]))
    return xp.sum(xp.asarray(offsets) * n0, axis=-1, keepdims=True) * n


def drive(
    points_map: Float[np.ndarray, "3P n_p"] | None,
    positions0: Float[np.ndarray, "P 3"],
    followed: Float[Array, "P 3"],
    change: Float[Array, " n_p"],
) -> Float[Array, "P 3"]:
    """The points ``followed`` (by :func:`follow`) with the coordinates that point
    parameters drive set to ``positions0 + points_map @ change`` (file units).

    The rule of a point parameter: it *is* the point's rest coordinate in its body's
    frame (bodies keep the identity orientation at rest, so the world axes), as a
    coordinate parameter is a joint's. A driven coordinate no longer follows the
    anchors (whatever the point's ``follow``); the others still do. So a coupler point
    with ``x`` and ``y`` driven is placed freely on its body in the plane, and a
    written design reads back with each parameter's value equal to the written
    coordinate. ``points_map`` ``(3P, n_p)``, None where no parameter drives a
    point; traceable in all but ``positions0`` (numpy where ``followed`` is)."""
    if points_map is None:
        return followed
    xp = np if isinstance(followed, np.ndarray) else jnp
    count = positions0.shape[0]
    points_map = xp.asarray(points_map)
    moved = (points_map @ change).reshape(count, 3)
    driven = xp.any(points_map != 0.0, axis=1).reshape(count, 3)
    return xp.where(driven, xp.asarray(positions0) + moved, followed)


def rest_points(mech, anchors, change) -> Float[Array, "P 3"]:
    """The named points' rest positions (file units) of the design whose anchors are
    ``anchors`` ``(J, 3)`` and whose change from the file's design is ``change``
    ``(n_p,)``: :func:`follow`, then :func:`drive`. numpy where ``anchors`` is."""
    followed = follow(
        mech.point_attachment, mech.point_positions, mech.anchors, anchors
    )
    return drive(mech.design.points, mech.point_positions, followed, change)
