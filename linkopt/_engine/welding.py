"""Welded parts: bodies joined by ``fixed`` joints are one rigid body.

A ``fixed`` joint gives 6 rows and its second body 7 state coordinates (and a unit
quaternion row); the rows cancel the coordinates, so the motion is that of the merged
body, but σ_min of the constraint Jacobian is not: the extra columns and rows change
its spectrum (an inert part welded onto a stick moved ``f_sing`` at one pose from 52.5
to 71.5). Pass or fail would depend on how a rigid part is modelled.

Decision: when a file loads, each group of bodies connected by ``fixed`` joints
becomes one engine body, its *root*: the ground when the group holds it, else the
group's first body in file order (:func:`weld`). Every metric (σ_min, f_sing, α₋,
f_design), FK/BK and mobility then see the mechanism with the group as one body, so
they are those of the same file without the welded parts. What stays as in the file:

* the joints: a ``fixed`` joint inside a group becomes a :data:`~.model.WELDED` joint
  of the root with itself, with no rows, so joint indices (design parameters, points,
  outputs, capsules) are unchanged and its anchor is still read out;
* joints, points, orientation outputs and capsules of a welded part are re-homed on its
  root: every body is at the identity orientation at rest and anchors are world
  positions at rest, so a part's geometry is the same in the root's frame;
* capsules stay one per original link, each with its own part's layer offset
  (``Collision.segment_layers``); checked pairs are between merged bodies, a pair
  inside one group is dropped (a weld does not collide with itself) and two pairs that
  become one are one pair;
* the file's mechanism, one body per part, is kept as ``Mechanism.welds.parts`` with
  the map from its bodies to the merged ones: exports (MJCF, URDF, meshes) and the
  design figure draw the parts, a merged state gives each part's pose by
  :func:`part_state`.

A file without ``fixed`` joints is returned as it is (same object, same fingerprint,
same programs). Idle spins are found on the file's bodies: a welded part makes its
rod a body of three joints, never idle.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from .model import WELDED, Collision, Mechanism, OutputTable


@dataclass(frozen=True, eq=False)
class Welds:
    """The parts of a welded mechanism: ``parts`` the file's mechanism (one body per
    part), ``body_of (B_parts,)`` the merged body of each part."""

    parts: Mechanism
    body_of: np.ndarray


def roots(mech: Mechanism) -> np.ndarray:
    """``(B,)``: the root part of each body's weld group (itself when unwelded); the
    ground roots its group, else the group's first body."""
    parent = np.arange(mech.num_bodies)

    def find(b: int) -> int:
        while parent[b] != b:
            b = parent[b]
        return b

    for joint in mech.joints_of("fixed"):
        a, b = (find(int(k)) for k in mech.joint_bodies[joint])
        if a != b:
            first = min(a, b, key=lambda k: -1 if k == mech.ground else k)
            parent[a + b - first] = first
    return np.array([find(b) for b in range(mech.num_bodies)])


def weld(mech: Mechanism) -> Mechanism:
    """``mech`` with each weld group merged into its root (module docstring)."""
    if not len(mech.joints_of("fixed")):
        return mech
    root = roots(mech)
    keep = np.flatnonzero(root == np.arange(mech.num_bodies))
    renumber = np.full(mech.num_bodies, -1)
    renumber[keep] = np.arange(len(keep))
    body_of = renumber[root]
    return dataclasses.replace(
        mech,
        body_names=tuple(mech.body_names[k] for k in keep),
        ground=int(body_of[mech.ground]),
        body_origins=mech.body_origins[keep],
        joint_types=tuple(WELDED if t == "fixed" else t for t in mech.joint_types),
        joint_bodies=body_of[mech.joint_bodies],
        point_bodies=body_of[mech.point_bodies],
        output_bodies=_bodies(mech.output_bodies, body_of),
        reported=_reported(mech.reported, body_of),
        idle_bodies=body_of[mech.idle_bodies],
        collision=_collision(mech.collision, body_of),
        welds=Welds(parts=mech, body_of=body_of),
    )


def _bodies(table: np.ndarray | None, body_of: np.ndarray) -> np.ndarray | None:
    """Body indices (-1: none) renumbered."""
    if table is None:
        return None
    return np.where(table >= 0, body_of[np.maximum(table, 0)], -1)


def _reported(table: OutputTable | None, body_of: np.ndarray) -> OutputTable | None:
    if table is None:
        return None
    return dataclasses.replace(table, bodies=_bodies(table.bodies, body_of))


def _collision(model: Collision | None, body_of: np.ndarray) -> Collision | None:
    """Capsules on their merged bodies with their own parts' layers; checked pairs
    between merged bodies, none inside a group, each once."""
    if model is None:
        return None
    merged = body_of[model.pairs] if len(model.pairs) else model.pairs
    pairs, owner_of = [], {}
    for a, b in merged:
        key = (min(a, b), max(a, b))
        if a != b and key not in owner_of:
            owner_of[key] = len(pairs)
            pairs.append(key)
    new_owner = np.array(
        [owner_of.get((min(a, b), max(a, b)), -1) for a, b in merged], dtype=int
    )
    owners = new_owner[model.capsule_owners] if len(model.capsule_owners) else []
    kept = np.flatnonzero(np.asarray(owners) >= 0)
    return dataclasses.replace(
        model,
        segment_bodies=body_of[model.segment_bodies],
        segment_layers=model.segment_bodies,
        pairs=np.array(pairs, dtype=int).reshape(-1, 2),
        capsule_pairs=model.capsule_pairs[kept],
        capsule_owners=np.asarray(owners, dtype=int)[kept],
    )


def parts(mech: Mechanism) -> Mechanism:
    """The mechanism with one body per part (the file's), for exports and drawings."""
    return mech if mech.welds is None else mech.welds.parts


def part_state(mech: Mechanism, state) -> np.ndarray:
    """A state of ``mech`` (homogenised, ``(..., 7B)``) as a state of its parts
    (``(..., 7 B_parts)``): each part at its root's pose, offset by where its origin
    lies in the root's frame."""
    state = np.asarray(state, dtype=float)
    if mech.welds is None:
        return state
    body_of, whole = mech.welds.body_of, mech.welds.parts
    frames = state.reshape(*state.shape[:-1], mech.num_bodies, 7)[..., body_of, :]
    offset = (whole.body_origins - mech.body_origins[body_of]) / mech.length_scale
    w, v = frames[..., 3:4], frames[..., 4:]
    t = 2.0 * np.cross(v, offset)
    turned = offset + w * t + np.cross(v, t)
    out = np.concatenate([frames[..., :3] + turned, frames[..., 3:]], axis=-1)
    return out.reshape(*state.shape[:-1], 7 * whole.num_bodies)
