"""Design parameters: ``[[parameters]]`` read into the linear map of a
:class:`~.model.DesignSpace` (the kinds in :mod:`.design_kinds`, the ``[symmetry]`` in
:mod:`.symmetry`).

Every parameter kind but the link angles (``twist``, :mod:`.design_angles`, turns
applied after the map) is a linear map onto the flat rest geometry (joint anchors and
primary axes, file units), so the optimiser, the partial gradient, the writer and
``verify`` treat them alike:

* ``coordinate`` (the default): one anchor coordinate or axis component of a joint
  (or of coincident joints), with optional ``ties`` (other joints' coordinates moved
  by ``factor`` times the same change) and symmetric images (``mirror``/``copies``);
* ``length``: the distance from the anchor of joint ``from`` to the centroid of the
  anchors of ``to`` (joints of ``body``); the ``to`` joints translate along the rest
  direction of that link, so the parameter *is* the link length;
* ``radius``: the distance of ``joints`` from an axis; each anchor moves radially;
* ``offset``: the distance between two parallel axes, moved like a length;
* ``point``: one rest coordinate of a named point on its body, a separate map
  (``DesignSpace.points``): the coordinates it drives no longer follow the anchors
  (:func:`linkopt._engine.following.drive`).

An axis component is one of the axis as the file writes it (:func:`_axis_lengths`):
the unit axis moves by the change over that length, so a design written with its axes
unnormalised reads back as the same parameters and the same map.

Why moving anchors keeps the rest pose assembled: the rest state is the body origins
with identity orientations, the same for every design, and a joint's local anchor in
each of its two bodies is its world anchor minus that body's origin, so every joint
residual is zero at rest whatever the anchors. What a design *can* break is a
compound joint: joints that share one anchor at rest (a spherical joint joining three
bodies, written as two joints) must stay at one point, so every joint coincident at
rest with a moved joint gets the same move (added here when a parameter names only
one of them; refused when a parameter moves them differently). Straight prismatic legs
(:func:`_legs`) follow their two ends, so a leg stays a leg.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from jaxtyping import Float

from .._engine.model import DesignSpace, Turns
from .._engine.symmetry import MIRROR_TOL, Symmetry
from .design_angles import turn_joints
from .design_kinds import read_parameter
from .design_moves import ANCHOR, AXIS, POINT, Context, Move
from .fields import Reader

__all__ = ["read_design"]


def read_design(
    rd: Reader,
    data: dict,
    joints: list[dict],
    body_index: dict[str, int],
    symmetry: Symmetry | None,
    scale: float,
    check_position: Callable[[str, object], None],
    points: tuple[dict, ...] = (),
    ground: int = -1,
) -> DesignSpace:
    """``[[parameters]]`` as a :class:`DesignSpace`; ``check_position(where, values)``
    raises for positions (bounds of lengths) beyond the loader's position bound;
    ``points`` the named points as read (for ``kind = "point"``), ``ground`` the
    ground body."""
    items = rd.entries(data, "parameters", required=False)
    rd.names(items, "parameters")
    joint_index = {j["name"]: k for k, j in enumerate(joints)}
    ctx = Context(
        rd,
        joints,
        joint_index,
        body_index,
        symmetry,
        scale,
        check_position,
        _axis_lengths(data, len(joints)),
        tuple(points),
        ground,
    )
    params = [
        read_parameter(ctx, item, f"parameters[{k}]") for k, item in enumerate(items)
    ]
    matrix = np.zeros((6 * len(joints) + 3 * len(points), len(items)))
    owner: dict[int, int] = {}
    links, turns = [], []
    for k, par in enumerate(params):
        where = f"parameters[{k}]"
        rows = _expanded_rows(ctx, where, par.moves)
        claimed = set(rows) | _link_rows(ctx, par.links) | _turn_rows(ctx, par.turns)
        _claim_rows(rd, where, k, rows, claimed, owner, matrix)
        links += [(where, source, target) for source, target in par.links]
        turns += [(k, turn) for turn in par.turns]
    _compose(ctx, matrix, links)
    _align_legs(ctx, matrix, owner)
    matrix, point_map = matrix[: 6 * len(joints)], matrix[6 * len(joints) :]
    return DesignSpace(
        tuple(i["name"] for i in items),
        np.array([p.value for p in params], dtype=float),
        np.array([p.low for p in params], dtype=float),
        np.array([p.high for p in params], dtype=float),
        matrix,
        np.array([p.is_length for p in params], dtype=bool),
        _turns(ctx, turns, matrix, links) if turns else None,
        point_map if np.any(point_map) else None,
    )


def _turn_rows(ctx: Context, turns) -> set[int]:
    """A twist owns the anchor and axis rows of the joints it turns."""
    return {
        _row(ctx, j, part, c)
        for turn in turns
        for j in ctx.coincident_all(turn.targets)
        for part in (ANCHOR, AXIS)
        for c in range(3)
    }


def _turns(ctx: Context, turns: list, matrix: np.ndarray, links: list) -> Turns:
    """The twists as :class:`Turns`; refused where a linear parameter moves a joint
    a twist turns or measures from (the twist's centre and normal would not follow),
    or measures from a turned joint (its far end would not turn)."""
    wheres = [f"parameters[{k}]" for k, _ in turns]
    ordered = turn_joints(ctx, wheres, turns)
    for k, turn, mask in ordered:
        for where, source, _ in links:
            if mask[source]:
                raise ctx.rd.fail(
                    where,
                    f"measured from joint {ctx.name(source)!r}, which "
                    f"parameters[{k}] (a twist) turns; expected a length or offset "
                    "from a joint that no twist turns",
                )
        for j in [turn.source, *np.flatnonzero(mask)]:
            rows = [_row(ctx, j, part, c) for part in (ANCHOR, AXIS) for c in range(3)]
            if np.any(matrix[rows]):
                raise ctx.rd.fail(
                    f"parameters[{k}]",
                    f"joint {ctx.name(j)!r} of this twist is also moved by a "
                    "parameter that is not a twist; expected a twist's joints moved "
                    "by twists only",
                )
    select = np.zeros((len(turns), matrix.shape[1]))
    for t, (k, _, _) in enumerate(ordered):
        select[t, k] = 1.0
    return Turns(
        select,
        np.array([turn.center for _, turn, _ in ordered]),
        np.array([turn.normal for _, turn, _ in ordered]),
        np.array([mask for _, _, mask in ordered]),
    )


def _axis_lengths(data: dict, count: int) -> np.ndarray:
    """The length of each joint's ``axis`` as the file writes it (1 where it has
    none). An axis-component parameter is a component of that written vector, so a
    design writes back unnormalised and reads back as the same parameters."""
    out = np.ones(count)
    for k, item in enumerate(data.get("joints", [])[:count]):
        if isinstance(item, dict) and "axis" in item:
            vec = np.asarray(item["axis"], dtype=float)
            largest = float(np.max(np.abs(vec)))
            out[k] = largest * float(np.linalg.norm(vec / largest))
    return out


# --- the matrix -----------------------------------------------------------------------


def _row(ctx: Context, joint: int, part: int, c: int) -> int:
    """The row of a joint's anchor or axis coordinate, or (``POINT``, ``joint`` the
    point's index) of a named point's, below the ``6 J`` rows of the joints."""
    return 3 * len(ctx.joints) * part + 3 * joint + c


def _expanded_rows(ctx: Context, where: str, moves: list[Move]) -> dict[int, float]:
    """Rows and weights of one parameter: its moves summed per joint, then every
    joint coincident at rest with a moved joint given the same anchor move."""
    anchor: dict[int, np.ndarray] = {}
    axis: dict[int, np.ndarray] = {}
    point: dict[int, np.ndarray] = {}
    for move in moves:
        table = {ANCHOR: anchor, AXIS: axis, POINT: point}[move.part]
        table[move.joint] = table.get(move.joint, np.zeros(3)) + move.vector
    for j in list(anchor):
        for other in ctx.coincident(j):
            if other not in anchor:
                anchor[other] = anchor[j]
            elif not np.allclose(anchor[other], anchor[j], rtol=0, atol=1e-12):
                raise ctx.rd.fail(
                    where,
                    f"joints {ctx.name(j)!r} and {ctx.name(other)!r} share their "
                    "anchor at rest and must move together; this parameter moves "
                    "them differently",
                )
    for j in axis:  # the unit axis moves by the written axis's move over its length
        axis[j] = axis[j] / ctx.axis_lengths[j]
    rows = {}
    for part, table in ((ANCHOR, anchor), (AXIS, axis), (POINT, point)):
        for j, vec in table.items():
            for c in range(3):
                if abs(vec[c]) > 1e-14 * np.max(np.abs(vec)):
                    rows[_row(ctx, j, part, c)] = float(vec[c])
    return rows


def _link_rows(ctx: Context, links) -> set[int]:
    """A length parameter owns every anchor row of its ``to`` joints (they follow
    ``from`` in all three coordinates)."""
    return {
        _row(ctx, t, ANCHOR, c)
        for _, targets in links
        for t in ctx.coincident_all(targets)
        for c in range(3)
    }


def _claim_rows(
    rd: Reader,
    where: str,
    k: int,
    rows: dict[int, float],
    claimed: set[int],
    owner: dict[int, int],
    matrix: Float[np.ndarray, "rows n_p"],
) -> None:
    """Parameter ``k`` takes the rows it drives; no row has two parameters (so that
    each parameter's rest value can be read back from a written design)."""
    for row in sorted(claimed):
        if row in owner:
            raise rd.fail(
                where,
                f"drives a coordinate already driven by parameters[{owner[row]}]",
            )
    for row in claimed:
        owner[row] = k
    for row, weight in rows.items():
        matrix[row, k] = weight


def _compose(ctx: Context, matrix: np.ndarray, links: list) -> None:
    """Each length parameter's ``to`` anchors also follow its ``from`` anchor: their
    rows get the ``from`` rows of every parameter. Links run upstream first (a chain
    of lengths composes); a loop of lengths is refused."""
    pending = list(links)
    while pending:
        moved = {t for _, _, targets in pending for t in ctx.coincident_all(targets)}
        ready = [link for link in pending if link[1] not in moved]
        if not ready:
            raise ctx.rd.fail(
                pending[0][0],
                "length parameters form a loop (each link's from joint is moved by "
                "another's); expected a chain from the ground",
            )
        for where, source, targets in ready:
            rows = slice(3 * source, 3 * source + 3)
            for t in ctx.coincident_all(targets):
                matrix[3 * t : 3 * t + 3] += matrix[rows]
            pending.remove((where, source, targets))


def _legs(ctx: Context) -> list[tuple[int, int, int, float, float]]:
    """Straight legs: a prismatic or cylindrical joint whose two bodies each have one
    other joint (the leg's ends ``e1``, ``e2``), its axis along ``e2 - e1`` and its
    anchor on that line at rest. Returns ``(joint, e1, e2, t, sign)``: the anchor's
    fraction along the leg and the axis's sign along ``e2 - e1``."""
    legs = []
    for p, joint in enumerate(ctx.joints):
        if joint["type"] not in ("prismatic", "cylindrical"):
            continue
        ends = [_only_other_joint(ctx, body, p) for body in joint["bodies"]]
        if min(ends) < 0:
            continue
        span = ctx.anchor(ends[1]) - ctx.anchor(ends[0])
        length = float(np.linalg.norm(span))
        if length <= ctx.tol:
            continue
        along = float(joint["axis"] @ span) / length
        offset = ctx.anchor(p) - ctx.anchor(ends[0])
        t = float(offset @ span) / length**2
        if (
            abs(abs(along) - 1.0) <= MIRROR_TOL
            and np.linalg.norm(offset - t * span) <= ctx.tol
        ):
            legs.append((p, ends[0], ends[1], t, np.sign(along) / length))
    return legs


def _only_other_joint(ctx: Context, body: int, joint: int) -> int:
    others = [i for i, j in enumerate(ctx.joints) if body in j["bodies"] and i != joint]
    return others[0] if len(others) == 1 else -1


def _align_legs(ctx: Context, matrix: np.ndarray, owner: dict[int, int]) -> None:
    """A straight leg (:func:`_legs`) stays straight: its prismatic joint's anchor
    keeps its fraction ``t`` along the leg and its axis follows the leg's direction
    (the axis is normalised in :func:`~.geometry.geometry`, so ``u0 + (Δe2 - Δe1)/L0``
    is exact: it is ``(e2 - e1)/L0`` at every design). Legs whose prismatic joint a
    parameter drives itself are left to that parameter."""
    base = 3 * len(ctx.joints)
    for p, e1, e2, t, scale in _legs(ctx):
        anchor_rows = range(3 * p, 3 * p + 3)
        axis_rows = range(base + 3 * p, base + 3 * p + 3)
        if any(r in owner for r in (*anchor_rows, *axis_rows)):
            continue
        first, second = matrix[3 * e1 : 3 * e1 + 3], matrix[3 * e2 : 3 * e2 + 3]
        matrix[3 * p : 3 * p + 3] = (1.0 - t) * first + t * second
        matrix[base + 3 * p : base + 3 * p + 3] = scale * (second - first)
