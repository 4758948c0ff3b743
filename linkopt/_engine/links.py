"""Link solids: which capsules make up each body, and which body pairs are checked for
collision (static, numpy; the distances are in :mod:`.collision`).

A body's solid is the set of capsules along the segments between its *places*: the
distinct rest positions of its joint anchors and named points (:func:`body_places`),
joined by :func:`segments` (every pair for up to four places, else a minimum spanning
tree). The exporters draw the same capsules (:mod:`linkopt._export.tree`), so what
``[collision]`` checks is what ``linkopt export`` writes. A place is an index into the
anchors followed by the named points (``j`` for joint ``j``, ``J + p`` for point
``p``), so a segment follows its body's anchors when a design moves them.

``[collision]`` and the per-body ``radius`` and ``layer`` are read by
:mod:`linkopt._files.collision`, which builds the model with :func:`build_collision`.
"""

from __future__ import annotations

from itertools import combinations

import numpy as np

from .model import Collision, Mechanism

#: Two places of a body closer than this (reference lengths) are one.
COINCIDENT = 1e-9
#: Default link thickness (capsule diameter) as a fraction of the reference length.
THICKNESS_FRACTION = 0.04
#: Default clearance band as a fraction of the thickness: half a thickness, so that two
#: links of the default thickness must stay one link radius apart.
CLEARANCE_FRACTION = 0.5


def default_thickness(length_scale: float) -> float:
    """The default link thickness (file units): :data:`THICKNESS_FRACTION` of the
    reference length, thin enough that the links of the shipped mechanisms stay apart
    at rest."""
    return THICKNESS_FRACTION * length_scale


def body_places(
    mech: Mechanism, anchors: np.ndarray, points: np.ndarray, body: int
) -> list[int]:
    """The places of ``body`` (module docstring) at the rest geometry
    ``anchors (J, 3)``, ``points (P, 3)`` (file units): its joints, then its named
    points, in file order; a place within :data:`COINCIDENT` reference lengths of an
    earlier one is left out. Empty for a body with neither joints nor points."""
    joints = len(anchors)
    refs = [int(j) for j in mech.joints_on(body)]
    refs += [joints + int(p) for p in np.flatnonzero(mech.point_bodies == body)]
    where = np.concatenate([np.reshape(anchors, (-1, 3)), np.reshape(points, (-1, 3))])
    tol = COINCIDENT * mech.length_scale
    distinct: list[int] = []
    for ref in refs:
        if all(np.linalg.norm(where[ref] - where[d]) > tol for d in distinct):
            distinct.append(ref)
    return distinct


def segments(places: np.ndarray) -> list[tuple[int, int]]:
    """Index pairs of the link segments drawn between a body's ``places (k, 3)``:
    every pair for up to four places (a triangle or tetrahedron of bars), else the
    edges of the minimum spanning tree (Prim), so that a ground with many anchors
    stays light."""
    k = len(places)
    if k <= 4:
        return [(a, b) for a in range(k) for b in range(a + 1, k)]
    inside, pairs = {0}, []
    while len(inside) < k:
        a, b = min(
            ((a, b) for a in inside for b in range(k) if b not in inside),
            key=lambda ab: np.linalg.norm(places[ab[0]] - places[ab[1]]),
        )
        pairs.append((a, b))
        inside.add(b)
    return pairs


def body_segments(
    mech: Mechanism, anchors: np.ndarray, points: np.ndarray, body: int
) -> list[tuple[int, int]]:
    """The capsules of ``body`` as place pairs (module docstring); a body with one
    place is one zero-length capsule (a sphere) at it."""
    refs = body_places(mech, anchors, points, body)
    where = np.concatenate([np.reshape(anchors, (-1, 3)), np.reshape(points, (-1, 3))])
    if len(refs) == 1:
        return [(refs[0], refs[0])]
    return [(refs[a], refs[b]) for a, b in segments(where[refs])]


def default_pairs(mech: Mechanism) -> set[tuple[int, int]]:
    """Every pair of bodies that share no joint (bodies in file order)."""
    joined = {tuple(sorted(int(b) for b in pair)) for pair in mech.joint_bodies}
    return {
        (a, b)
        for a, b in combinations(range(mech.num_bodies), 2)
        if (a, b) not in joined
    }


def build_collision(
    mech: Mechanism,
    enabled: bool,
    clearance: float,
    weight: float,
    radii: np.ndarray,
    offsets: np.ndarray,
    pairs: set[tuple[int, int]],
) -> Collision:
    """The static collision model: capsules of every body at the file's initial
    design (:func:`body_segments`) and the capsule pairs of the checked body pairs."""
    seg_bodies, seg_places = [], []
    for body in range(mech.num_bodies):
        for ends in body_segments(mech, mech.anchors, mech.point_positions, body):
            seg_bodies.append(body)
            seg_places.append(ends)
    seg_bodies = np.array(seg_bodies, dtype=int)
    body_pairs = np.array(sorted(pairs), dtype=int).reshape(-1, 2)
    capsule_pairs, owners = [], []
    for q, (a, b) in enumerate(body_pairs):
        for i in np.flatnonzero(seg_bodies == a):
            for k in np.flatnonzero(seg_bodies == b):
                capsule_pairs.append((i, k))
                owners.append(q)
    return Collision(
        enabled=bool(enabled),
        clearance=float(clearance),
        weight=float(weight),
        segment_bodies=seg_bodies,
        segment_places=np.array(seg_places, dtype=int).reshape(-1, 2),
        segment_radii=np.asarray(radii, dtype=float)[seg_bodies],
        body_offsets=np.asarray(offsets, dtype=float).reshape(-1, 3),
        body_radii=np.asarray(radii, dtype=float),
        pairs=body_pairs,
        capsule_pairs=np.array(capsule_pairs, dtype=int).reshape(-1, 2),
        capsule_owners=np.array(owners, dtype=int),
    )
