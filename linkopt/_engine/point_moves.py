"""Named points that a design moves far on their bodies.

A point that follows its body's anchors (``[[points]].follow = "anchors"``,
:mod:`.attachment`) moves when a design moves them: a pin moved on a two-joint stick
can carry the stick's tip a long way, and an optimiser will use it. This module says
where that happens, so that ``linkopt check`` (over the design box), ``linkopt
evaluate`` (for its design) and the design figure can show it.

The measure: how far a point's rest position at a design lies from the initial design's,
after both are taken relative to the centroid of its body's anchors (a design that
carries all of a body's anchors along, as a delta's longer rods carry its platform,
moves the body, not the point on it), compared with the body's size, its *anchor span*
(the largest distance between two of the body's joint anchors at the initial design; the
reference length for a body whose anchors are all at one place). A move larger than
:data:`MOVE_SHARE` of the span is reported. Points fixed in their frame never move, and
points that follow one joint (given by ``joint`` or on an anchor) move as that joint
does, which the design parameter states; neither is reported, nor is a point that a
point parameter (``kind = "point"``) drives.

Over the design box, the in-hull part of a followed point is linear in the design, so
its largest move lies at a corner of the box: every corner is tried for up to
:data:`CORNERS` parameters, else each parameter at its two bounds (the others at the
initial design) and the two corners of all lower and all upper bounds.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np

from .attachment import follows_one_joint
from .following import rest_points
from .model import Mechanism

#: A point moved farther than this share of its body's anchor span is reported.
MOVE_SHARE = 0.10
#: Up to this many design parameters, every corner of the design box is tried.
CORNERS = 10


@dataclass(frozen=True)
class PointMove:
    """A named point that a design moves by more than :data:`MOVE_SHARE` of its
    body's anchor span: ``rest`` and ``moved`` ``(3,)`` its rest positions at the
    initial design and at ``design`` ``(n_p,)`` (file units), ``distance`` how far it
    moved relative to the centroid of its body's anchors, ``size`` the body's anchor
    span (file units)."""

    point: str
    body: str
    distance: float
    size: float
    rest: np.ndarray
    moved: np.ndarray
    design: np.ndarray

    @property
    def share(self) -> float:
        return self.distance / self.size

    def as_json(self, names: tuple[str, ...]) -> dict:
        return {
            "point": self.point,
            "body": self.body,
            "distance": self.distance,
            "body_span": self.size,
            "share": self.share,
            "rest": [float(v) for v in self.rest],
            "moved": [float(v) for v in self.moved],
            "design": dict(zip(names, map(float, self.design))),
        }

    def line(self, units: str = "") -> str:
        """One line for the command line."""
        unit = f" {units}" if units else ""
        return (
            f"point {self.point!r} on {self.body!r} moves {self.distance:.4g}{unit} "
            "relative to its body's anchors "
            f"({100 * self.share:.3g} % of the body's anchor span "
            f"{self.size:.4g}{unit}); it follows the anchors "
            '(follow = "anchors"): give follow = "frame" to keep it fixed on '
            "its body"
        )


def anchor_spans(mech: Mechanism) -> np.ndarray:
    """``(B,)``: each body's anchor span at the initial design (file units), the
    reference length where its anchors are all at one place."""
    spans = np.full(mech.num_bodies, float(mech.length_scale))
    for body in range(mech.num_bodies):
        anchors = mech.anchors[mech.joints_on(body)]
        if len(anchors) > 1:
            gaps = np.linalg.norm(anchors[:, None] - anchors[None], axis=-1).max()
            if gaps > 0.0:
                spans[body] = gaps
    return spans


def box_designs(mech: Mechanism) -> np.ndarray:
    """``(N, n_p)``: the designs ``linkopt check`` tries (module docstring)."""
    space = mech.design
    if space.size == 0:
        return space.p0[None]
    if space.size <= CORNERS:
        pick = np.array(list(itertools.product((0, 1), repeat=space.size)), bool)
        return np.where(pick, space.upper, space.lower)
    rows = [space.lower, space.upper]
    for k in range(space.size):
        for bound in (space.lower[k], space.upper[k]):
            row = space.p0.copy()
            row[k] = bound
            rows.append(row)
    return np.array(rows)


def point_moves(mech: Mechanism, designs) -> tuple[PointMove, ...]:
    """The points that one of ``designs`` ``(N, n_p)`` (file units) moves by more
    than :data:`MOVE_SHARE` of their body's anchor span, each at the design that
    moves it most; file order."""
    designs = np.atleast_2d(np.asarray(designs, dtype=float))
    weights = mech.point_attachment.weights
    fixed = ~np.any(weights != 0.0, axis=1)  # fixed in their frame
    driven = _driven(mech)  # a point parameter states its move
    candidates = np.flatnonzero(
        ~follows_one_joint(mech.point_attachment) & ~fixed & ~driven
    )
    if len(candidates) == 0 or mech.design.size == 0:
        return ()
    rest, moved, anchors = _rest_points(mech, designs)
    carried = _centroids(mech, anchors - mech.anchors[None])  # (N, P, 3)
    distance = np.linalg.norm(moved - rest[None] - carried, axis=-1)  # (N, P)
    spans = anchor_spans(mech)
    found = []
    for k in candidates:
        worst = int(np.argmax(distance[:, k]))
        size = float(spans[mech.point_bodies[k]])
        if distance[worst, k] > MOVE_SHARE * size:
            found.append(
                PointMove(
                    point=mech.point_names[k],
                    body=mech.body_names[mech.point_bodies[k]],
                    distance=float(distance[worst, k]),
                    size=size,
                    rest=rest[k],
                    moved=moved[worst, k],
                    design=designs[worst],
                )
            )
    return tuple(found)


def _driven(mech: Mechanism) -> np.ndarray:
    """``(P,)`` bool: the points a ``kind = "point"`` parameter drives."""
    count = len(mech.point_names)
    if mech.design.points is None:
        return np.zeros(count, dtype=bool)
    moved = np.any(mech.design.points != 0.0, axis=1).reshape(count, 3)
    return np.any(moved, axis=1)


def _rest_points(mech: Mechanism, designs: np.ndarray):
    """The points' rest positions at the initial design ``(P, 3)`` and at each design
    ``(N, P, 3)``, and the anchors ``(N, J, 3)``, file units: :func:`.geometry.geometry`
    in numpy (no tracing, so a check of a thousand corners takes milliseconds)."""
    space, count = mech.design, len(mech.anchors)
    flat = space.matrix[: 3 * count] @ (designs - space.p0).T  # (3J, N)
    anchors = mech.anchors[None] + flat.T.reshape(-1, count, 3)
    rest = mech.point_positions
    changes = designs - space.p0
    moved = np.array([rest_points(mech, a, d) for a, d in zip(anchors, changes)])
    return rest, moved.reshape(len(designs), -1, 3), anchors


def _centroids(mech: Mechanism, shifts: np.ndarray) -> np.ndarray:
    """``(N, P, 3)``: the mean of ``shifts`` ``(N, J, 3)`` over each point's body's
    joints."""
    out = np.zeros((len(shifts), len(mech.point_names), 3))
    for k, body in enumerate(mech.point_bodies):
        joints = mech.joints_on(body)
        if len(joints):
            out[:, k] = shifts[:, joints].mean(axis=1)
    return out
