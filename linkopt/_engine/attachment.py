"""Named points attached to their bodies: where a point is at the rest pose of any
design.

A design moves joint anchors (:mod:`.design_space`); each named point has one of two
rules, the file's choice (``[[points]].follow``), fixed at load from the
file's initial design:

* ``"frame"`` (the default): the point is fixed in its body's frame. Body origins never
  move with the design and every body has the identity orientation at rest, so its
  rest position is the same for every design: moving a pin on a part moves none of the
  part's other features.
* ``"anchors"``: the point follows its body's anchors, so that a tool point written at
  a platform's centre stays at the centre when the design changes the rods. A point
  given by ``joint``, or by a ``position`` that coincides with one of its body's
  anchors (within :data:`COINCIDENT` reference lengths), follows that anchor (a point
  given by ``joint`` always does, whatever the rule).
* Any other point that follows the anchors keeps its affine coordinates with respect to
  its body's anchors: the part of it inside their affine hull (a line for two distinct
  anchors, a plane for three or more in one plane, all of space otherwise) is the
  least-norm affine combination ``Σ w_i a_i`` (``Σ w_i = 1``) of the anchors, and the
  rest, its offset ``d`` from the hull, keeps its length and turns with the hull: along
  the unit normal of a plane hull, by the smallest rotation taking the old line
  direction to the new one for a line hull, unchanged for a body with a single anchor
  position.

For designs that move a body's anchors rigidly this is the rigid motion of the body; for
designs that stretch it (a longer link, a wider platform) the point keeps its place
among the anchors (a point at the centroid of a platform's joints stays at their
centroid). A point fixed in its frame has zero weights and the :data:`POINT` hull, so
the same traced code gives its constant position. The weights, offsets and hull
directions are static (numpy); the map from anchors to points is linear for the in-hull
part, so it is smooth in the design and its derivatives come from JAX.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from jaxtyping import Float

#: A point this close to an anchor of its body (in reference lengths) follows it.
COINCIDENT = 1e-9
#: Relative size below which a singular value of a body's centred anchors counts as
#: zero (the anchors span fewer dimensions).
FLAT = 1e-9

#: Hull kinds: a single anchor position, a line, a plane, all of space.
POINT, LINE, PLANE, SPACE = 0, 1, 2, 3


@dataclass(frozen=True, eq=False)
class Attachment:
    """How the ``P`` named points follow the ``J`` joint anchors (static).

    ``weights (P, J)``: the affine weights of each point's in-hull part (a row sums to
    one). ``offsets (P, 3)``: the offset from the hull at the initial design, file
    units. ``spans (P, 2, J)``: coefficients giving the hull's directions as linear
    combinations of the anchors, ``e_k = spans[p, k] @ anchors`` (unit at the initial
    design). ``hulls (P,)``: :data:`POINT`, :data:`LINE`, :data:`PLANE` or
    :data:`SPACE`.
    """

    weights: np.ndarray
    offsets: np.ndarray
    spans: np.ndarray
    hulls: np.ndarray

    @classmethod
    def empty(cls, joints: int) -> Attachment:
        return cls(
            np.zeros((0, joints)),
            np.zeros((0, 3)),
            np.zeros((0, 2, joints)),
            np.zeros(0, dtype=int),
        )


def attach(
    anchors: Float[np.ndarray, "J 3"],
    on_body: list[np.ndarray],
    positions: Float[np.ndarray, "P 3"],
    follows: np.ndarray,
    scale: float,
    fixed: np.ndarray | None = None,
) -> Attachment:
    """The :class:`Attachment` of points at ``positions`` (rest, initial design, file
    units); ``on_body[p]`` the joints of point ``p``'s body, ``follows[p]`` the joint
    it follows or -1, ``scale`` the reference length, ``fixed[p]`` whether the point is
    fixed in its body's frame (default: none is; a point with ``follows[p] >= 0``
    follows its joint either way)."""
    if fixed is None:
        fixed = np.zeros(len(positions), dtype=bool)
    rows = [
        _fixed(len(anchors))
        if still and joint < 0
        else _one(anchors, joints, position, joint, scale)
        for joints, position, joint, still in zip(on_body, positions, follows, fixed)
    ]
    if not rows:
        return Attachment.empty(len(anchors))
    weights, offsets, spans, hulls = zip(*rows)
    return Attachment(
        np.array(weights), np.array(offsets), np.array(spans), np.array(hulls)
    )


def _fixed(count: int):
    """A point fixed in its body's frame: no weights, no offset, nothing to turn."""
    return np.zeros(count), np.zeros(3), np.zeros((2, count)), POINT


def follows_one_joint(attachment: Attachment) -> np.ndarray:
    """``(P,)`` bool: the points that follow a single joint's anchor (given by
    ``joint`` or on an anchor): a design moves them as it moves that joint."""
    return np.count_nonzero(attachment.weights, axis=1) == 1


def _one(anchors, joints, position, joint, scale):
    count = len(anchors)
    weights, spans = np.zeros(count), np.zeros((2, count))
    if joint < 0:
        near = np.linalg.norm(anchors[joints] - position, axis=1)
        if len(near) and near.min() <= COINCIDENT * scale:
            joint = int(joints[np.argmin(near)])
    if joint >= 0:
        weights[joint] = 1.0
        return weights, np.zeros(3), spans, SPACE
    centre = anchors[joints].mean(axis=0)
    centred = anchors[joints] - centre
    _, sv, vt = np.linalg.svd(centred, full_matrices=False)
    rank = int(np.sum(sv > FLAT * max(scale, sv[0] if len(sv) else 0.0)))
    basis = vt[:rank]
    inside = basis.T @ (basis @ (position - centre))
    # least-norm affine weights: centred columns sum to zero, so Σ w = 1 holds
    local = centred @ basis.T / sv[:rank] ** 2 @ (basis @ inside) if rank else 0.0
    weights[joints] = 1.0 / len(joints) + local
    for k in range(min(rank, 2)):
        spans[k, joints] = centred @ basis[k] / sv[k] ** 2
    return weights, position - centre - inside, spans, rank
