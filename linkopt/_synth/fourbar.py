"""Closed forms of the planar four-bar (numpy, at file time): Grashof class,
transmission angle and link ratio, Freudenstein's function generation and
precision-point path generation, and the four-bar of a mechanism file read off and
written back.

Names (Norton's): ground pivots ``A`` (the input, driven) and ``D``; crank ``a = |AB|``,
coupler ``b = |BC|``, rocker ``c = |DC|``, ground ``d = |AD|``. Angles are measured
from the ground line ``A -> D``: the crank ``φ`` (of ``B - A``), the rocker ``ψ`` (of
``C - D``). The transmission angle ``μ`` is the angle at ``C`` between the coupler and
the rocker, ``cos μ = (b² + c² − a² − d² + 2ad cos φ) / (2bc)`` (law of cosines in the
triangles ``ABD`` and ``BCD``); it is the same on both assembly branches.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .._engine.geometry import moved_joints
from .._engine.model import Mechanism
from .._errors import InputError

#: A fitted link shorter than this fraction of the target points' extent makes the
#: four-bar degenerate (both dyads the same: no coupler, or no ground link).
DEGENERATE = 1e-3
#: Relative tolerance of ``s + l = p + q`` (a change-point four-bar).
CHANGE_POINT_TOLERANCE = 1e-12


@dataclass(frozen=True)
class FourBar:
    """Link lengths (file units) and the coupler point ``(u, v)``: ``u`` along
    ``B -> C``, ``v`` to its left, from ``B``."""

    crank: float
    coupler: float
    rocker: float
    ground: float
    point: tuple[float, float] = (0.0, 0.0)

    @property
    def lengths(self) -> np.ndarray:
        """``(a, b, c, d)``, shape ``(4,)``."""
        return np.array([self.crank, self.coupler, self.rocker, self.ground])


def grashof_class(four_bar: FourBar) -> str:
    """Grashof's class: with ``s``/``l`` the shortest/longest link and ``p``, ``q``
    the others, ``s + l < p + q`` gives (by the shortest link) ``"crank-rocker"``
    (the crank), ``"double-crank"`` (the ground: a drag link), ``"rocker-crank"``
    (the rocker) or ``"double-rocker"`` (the coupler); ``s + l = p + q`` is
    ``"change-point"``; ``s + l > p + q`` is ``"triple-rocker"`` (no link turns
    fully)."""
    lengths = np.abs(four_bar.lengths)
    order = np.sort(lengths)
    excess = order[0] + order[3] - order[1] - order[2]
    if abs(excess) <= CHANGE_POINT_TOLERANCE * order[3]:
        return "change-point"
    if excess > 0:
        return "triple-rocker"
    shortest = int(np.argmin(lengths))
    return ("crank-rocker", "double-rocker", "rocker-crank", "double-crank")[shortest]


def full_turn_crank(four_bar: FourBar) -> bool:
    """Whether the input link turns fully relative to the ground (crank-rocker or
    double-crank; a change-point four-bar does too, through its change points)."""
    kind = grashof_class(four_bar)
    lengths = np.abs(four_bar.lengths)
    if kind == "change-point":
        return bool(lengths[0] == lengths.min() or lengths[3] == lengths.min())
    return kind in ("crank-rocker", "double-crank")


def link_ratio(four_bar: FourBar) -> float:
    """Longest link over shortest."""
    lengths = np.abs(four_bar.lengths)
    return float(lengths.max() / lengths.min())


@dataclass(frozen=True)
class Transmission:
    """Least and greatest transmission angle ``μ`` over the motion (rad, in
    ``[0, π]``); ``worst`` its least distance from a straight line,
    ``min(least, π − greatest)`` (the design rule asks 40° or more)."""

    least: float
    greatest: float

    @property
    def worst(self) -> float:
        return float(min(self.least, np.pi - self.greatest))


def transmission(four_bar: FourBar) -> Transmission:
    """:class:`Transmission` in closed form. ``cos μ`` is linear in ``cos φ``, so over
    the reachable crank angles (where ``|cos μ| ≤ 1``) its extremes are at ``φ = 0``
    and ``φ = π``, clipped to ``±1`` (a toggle, ``μ`` 0 or π) where those are not
    reached: ``cos μ_min = (b² + c² − (d − a)²) / 2bc``, ``cos μ_max = (b² + c² −
    (d + a)²) / 2bc``."""
    a, b, c, d = np.abs(four_bar.lengths)
    near = (b * b + c * c - (d - a) ** 2) / (2 * b * c)
    far = (b * b + c * c - (d + a) ** 2) / (2 * b * c)
    return Transmission(
        float(np.arccos(np.clip(near, -1, 1))), float(np.arccos(np.clip(far, -1, 1)))
    )


# ---------------------------------------------------------------------------------
# Function generation (Freudenstein)


@dataclass(frozen=True)
class FunctionFit:
    """Freudenstein's three-point solution: ``k = (K1, K2, K3)`` of
    ``K1 cos ψ − K2 cos φ + K3 = cos(φ − ψ)``, ``K1 = d/a``, ``K2 = d/c``,
    ``K3 = (a² − b² + c² + d²) / 2ac``, and the signed lengths it gives: a negative
    ``crank`` (``rocker``) points opposite to the angle ``φ`` (``ψ``), that is, the
    link's angle is ``φ + π``."""

    k: np.ndarray  # (3,)
    crank: float
    coupler: float
    rocker: float
    ground: float

    def four_bar(self) -> FourBar:
        return FourBar(abs(self.crank), self.coupler, abs(self.rocker), self.ground)


def freudenstein(phi, psi, *, ground: float = 1.0) -> FunctionFit:
    """The four-bar whose rocker angle is ``psi[i]`` at crank angle ``phi[i]``, for
    three precision pairs (rad, from the ground line), ground length ``ground``.

    The equation (from ``|C − B|² = b²`` with ``B = a e^{iφ}``, ``C = d + c e^{iψ}``)
    is linear in ``K``: a 3x3 solve. :class:`InputError` when the pairs give a
    singular system or ``b² ≤ 0`` (no real coupler)."""
    phi, psi = np.asarray(phi, dtype=float), np.asarray(psi, dtype=float)
    if phi.shape != (3,) or psi.shape != (3,):
        raise InputError(f"phi, psi: expected three angles each, got {phi.shape}")
    system = np.stack([np.cos(psi), -np.cos(phi), np.ones(3)], axis=1)
    if np.linalg.cond(system) > 1e12:
        raise InputError("phi, psi: the three precision pairs give a singular system")
    k = np.linalg.solve(system, np.cos(phi - psi))
    a, c, d = ground / k[0], ground / k[1], ground
    squared = a * a + c * c + d * d - 2 * a * c * k[2]
    if squared <= 0:
        raise InputError(f"phi, psi: no real coupler (b² = {squared:.3g})")
    return FunctionFit(k, float(a), float(np.sqrt(squared)), float(c), float(d))


# ---------------------------------------------------------------------------------
# Path generation: precision points (dyads in standard form)


@dataclass(frozen=True)
class PlacedFourBar:
    """A four-bar in place, at one pose: pivots ``A``, ``D``, pins ``B``, ``C`` and the
    coupler point ``P``, each ``(2,)`` in the plane whose origin and axes are the rows
    of ``plane`` ``(3, 3)`` (world point ``origin + x e1 + y e2``; default the world
    ``xy`` plane)."""

    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    D: np.ndarray
    P: np.ndarray
    plane: np.ndarray = field(default_factory=lambda: np.eye(3, k=-1))

    def four_bar(self) -> FourBar:
        """Lengths and the coupler point in the coupler's frame."""
        a, b = np.linalg.norm(self.B - self.A), np.linalg.norm(self.C - self.B)
        c, d = np.linalg.norm(self.C - self.D), np.linalg.norm(self.D - self.A)
        e = (self.C - self.B) / b
        offset = self.P - self.B
        u, v = offset @ e, offset @ np.array([-e[1], e[0]])
        return FourBar(float(a), float(b), float(c), float(d), (float(u), float(v)))

    @property
    def crank_angle(self) -> float:
        """``φ`` at this pose, from the ground line (rad)."""
        return float(_angle(self.B - self.A) - _angle(self.D - self.A))

    def world(self, point: np.ndarray) -> np.ndarray:
        """A plane point ``(2,)`` in world coordinates ``(3,)``."""
        return self.plane[0] + point[0] * self.plane[1] + point[1] * self.plane[2]


def _angle(v: np.ndarray) -> float:
    return float(np.arctan2(v[1], v[0]))


def _dyad(delta, coupler_turns, link_turns):
    """``W``, ``Z`` (complex) of the standard form ``W (e^{iβj} − 1) + Z (e^{iαj} −
    1) = δj``, least squares over ``j`` (exact for two equations), and the
    residual."""
    system = np.stack([np.exp(1j * link_turns) - 1, np.exp(1j * coupler_turns) - 1], 1)
    solution = np.linalg.lstsq(system, delta, rcond=None)[0]
    return solution, system @ solution - delta


def precision_path(points, coupler_turns, crank_turns, rocker_turns) -> PlacedFourBar:
    """The four-bar whose coupler point passes through ``points`` ``(n, 2)`` with the
    coupler turned by ``coupler_turns[j-1]`` (rad), the crank by ``crank_turns`` and
    the rocker by ``rocker_turns`` from point 1 to point ``j`` (the free choices of
    the dyad standard form, Sandor and Erdman); placed at point 1. Exact for three
    points (two complex 2x2 solves); for four or five, each dyad is the least-squares
    solution (:func:`fit_path` picks the turns that make it exact)."""
    points = np.asarray(points, dtype=float)
    z = points[:, 0] + 1j * points[:, 1]
    delta = z[1:] - z[0]
    alpha = np.asarray(coupler_turns, dtype=float)
    (w, zl), _ = _dyad(delta, alpha, np.asarray(crank_turns, dtype=float))
    (u, zr), _ = _dyad(delta, alpha, np.asarray(rocker_turns, dtype=float))
    a0, b0 = z[0] - zl - w, z[0] - zr - u

    def xy(c):
        return np.array([c.real, c.imag])

    return PlacedFourBar(xy(a0), xy(a0 + w), xy(b0 + u), xy(b0), points[0].copy())


def _fit_residual(turns, delta):
    alpha, beta, gamma = np.split(turns, 3)
    _, left = _dyad(delta, alpha, beta)
    _, right = _dyad(delta, alpha, gamma)
    both = np.concatenate([left, right])
    return np.concatenate([both.real, both.imag])


@dataclass(frozen=True)
class PathFit:
    """A precision-point four-bar (:func:`fit_path`): the linkage placed at point 1,
    the turns (rad, from point 1 to each further point) and the dyads' residual
    (file units; zero when every point is met exactly)."""

    placed: PlacedFourBar
    coupler_turns: np.ndarray  # (n - 1,)
    crank_turns: np.ndarray  # (n - 1,)
    rocker_turns: np.ndarray  # (n - 1,)
    residual: float

    def one_circuit(self) -> bool:
        """Whether every point is met on the circuit of the first: the triangle
        ``B C D`` keeps its orientation (a full-turn crank never flattens it), with
        ``B`` turned about ``A`` by the crank turns and ``C`` about ``D`` by the
        rocker's. False is the classic branch (circuit) defect."""
        p = self.placed
        pins = _turned(p.B - p.A, self.crank_turns) + p.A
        rockers = _turned(p.C - p.D, self.rocker_turns) + p.D
        pins, rockers = np.vstack([p.B, pins]), np.vstack([p.C, rockers])
        side = np.sign(_cross(rockers - pins, p.D - rockers))
        return bool(np.all(side == side[0]) and side[0] != 0)

    def in_order(self, closed: bool) -> bool:
        """Whether the crank meets the points in their order, turning one way: an
        open curve within one turn, a closed one once around."""
        turns = np.r_[0.0, self.crank_turns]
        sense = np.sign(turns[1])
        if closed:
            turns = np.mod(sense * turns, 2 * np.pi)
            return bool(np.all(np.diff(turns) > 0))
        steps = np.diff(sense * turns)
        return bool(np.all(steps > 0) and abs(turns[-1]) < 2 * np.pi)


def _turned(v: np.ndarray, angles: np.ndarray) -> np.ndarray:
    """``v`` ``(2,)`` turned by each of ``angles``: ``(n, 2)``."""
    c, s = np.cos(angles), np.sin(angles)
    return np.stack([c * v[0] - s * v[1], s * v[0] + c * v[1]], axis=1)


def _cross(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    return u[..., 0] * v[..., 1] - u[..., 1] * v[..., 0]


def fit_path(points, *, seed: int, closed: bool = False, starts: int = 12) -> PathFit:
    """Precision-point path generation for three to five points ``(n, 2)``: the
    coupler, crank and rocker turns of :func:`precision_path` found by nonlinear least
    squares on the dyads' residuals (scipy's ``least_squares``) from ``starts`` random
    turns drawn from ``seed``. Three points are met exactly whatever the turns; four
    and five (Burmester's exact cases) where the fit reaches zero residual, else in
    the least-squares sense (``residual`` says which). Degenerate fits (two
    coinciding dyads: a coupler or ground shorter than ``DEGENERATE`` of the points'
    extent) are dropped; the others ranked: free of branch and order defects
    (:meth:`PathFit.one_circuit`, :meth:`PathFit.in_order`), a full-turn crank, the
    least residual, then the best transmission angle; the first is returned."""
    from scipy.optimize import least_squares

    points = np.asarray(points, dtype=float)
    if points.ndim != 2 or points.shape[1] != 2 or not 3 <= len(points) <= 5:
        raise InputError(f"points: expected (3..5, 2) points, got {points.shape}")
    z = points[:, 0] + 1j * points[:, 1]
    delta, n = z[1:] - z[0], len(points) - 1
    size = float(np.linalg.norm(np.ptp(points, axis=0)))
    rng = np.random.default_rng(seed)
    best = None
    for _ in range(starts):
        turns = np.sort(rng.uniform(0.2, 2 * np.pi - 0.2, (3, n)), axis=1)
        turns = (turns * rng.choice([-1.0, 1.0], (3, 1))).ravel()
        solved = least_squares(
            _fit_residual, turns, args=(delta,), xtol=1e-15, ftol=1e-15, gtol=1e-15
        ).x
        residual = float(np.max(np.abs(_fit_residual(solved, delta))))
        fit = PathFit(
            precision_path(points, *np.split(solved, 3)), *np.split(solved, 3), residual
        )
        if _degenerate(fit.placed, size):
            continue
        four_bar = fit.placed.four_bar()
        key = (
            not fit.one_circuit(),
            not fit.in_order(closed),
            not full_turn_crank(four_bar),
            round(residual / size, 9),
            -transmission(four_bar).worst,
        )
        if best is None or key < best[0]:
            best = (key, fit)
    if best is None:
        raise InputError(
            f"points: no four-bar from {starts} starts (every fit degenerate)"
        )
    return best[1]


def _degenerate(placed: PlacedFourBar, size: float) -> bool:
    with np.errstate(divide="ignore", invalid="ignore"):
        lengths = placed.four_bar().lengths
    return bool(np.min(np.abs(lengths)) < DEGENERATE * size)


# ---------------------------------------------------------------------------------
# A mechanism file's four-bar


@dataclass(frozen=True)
class FourBarJoints:
    """Indices of a four-bar mechanism's joints ``A`` (the motor's, on the ground),
    ``B`` (crank-coupler), ``C`` (coupler-rocker), ``D`` (rocker-ground), its coupler
    body and its coupler point (-1: none)."""

    A: int
    B: int
    C: int
    D: int
    coupler: int
    point: int


def four_bar_joints(mech: Mechanism, point: str | None = None) -> FourBarJoints:
    """The four-bar's joints (:class:`FourBarJoints`); :class:`InputError` naming the
    file when it is not a one-motor four-bar of revolute joints with parallel axes."""
    bodies, kinds = mech.joint_bodies, mech.joint_types
    shaped = (
        mech.num_bodies == 4
        and len(kinds) == 4
        and set(kinds) == {"revolute"}
        and mech.num_motors == 1
        and np.allclose(np.abs(mech.axes @ mech.axes[0]), 1.0, atol=1e-9)
    )
    a = int(mech.motor_joints[0]) if shaped else -1
    if not shaped or mech.ground not in bodies[a]:
        raise InputError(
            f"{mech.source}: not a planar four-bar (4 bodies, 4 parallel revolute "
            "joints, one motor on a ground joint)"
        )
    crank = int(bodies[a][bodies[a] != mech.ground][0])
    d = next(j for j in range(4) if j != a and mech.ground in bodies[j])
    rocker = int(bodies[d][bodies[d] != mech.ground][0])
    b = next(j for j in range(4) if j not in (a, d) and crank in bodies[j])
    c = next(j for j in range(4) if j not in (a, b, d))
    coupler = next(i for i in range(4) if i not in (mech.ground, crank, rocker))
    return FourBarJoints(a, b, c, d, coupler, _coupler_point(mech, coupler, point))


def _coupler_point(mech: Mechanism, coupler: int, point: str | None) -> int:
    if point is None:
        on = np.flatnonzero(np.asarray(mech.point_bodies) == coupler)
        return int(on[0]) if len(on) else -1
    if point not in mech.point_names:
        raise InputError(f"point: {point!r} is not a point of {mech.source}")
    return mech.point_names.index(point)


def _plane(axis: np.ndarray, origin: np.ndarray) -> np.ndarray:
    """Rows origin, e1, e2 of the plane normal to ``axis``; the world ``x``, ``y``
    when the axis is ``±z``."""
    axis = axis / np.linalg.norm(axis)
    if abs(axis[2]) > 1 - 1e-12:
        e1 = np.array([1.0, 0.0, 0.0])
    else:
        e1 = np.cross([0.0, 0.0, 1.0], axis)
        e1 /= np.linalg.norm(e1)
    return np.stack([origin, e1, np.cross(axis, e1) * np.sign(axis[2] or 1.0)])


def read_four_bar(
    mech: Mechanism, design=None, point: str | None = None
) -> PlacedFourBar:
    """The four-bar of ``mech`` at its rest pose for ``design`` (None: the file's), in
    the plane of its joints (through ``A``); ``P`` the named coupler point (None: the
    coupler's first, else ``B``)."""
    from .._engine.geometry import geometry

    joints = four_bar_joints(mech, point)
    anchors, axes = (np.asarray(v) for v in moved_joints(mech, design))
    plane = _plane(axes[joints.A], anchors[joints.A])
    places = np.asarray(geometry(mech, design).points) * mech.length_scale

    def flat(x):
        return (plane[1:] @ (x - plane[0])).astype(float)

    p = anchors[joints.B] if joints.point < 0 else places[joints.point]
    picked = [anchors[j] for j in (joints.A, joints.B, joints.C, joints.D)]
    return PlacedFourBar(*(flat(x) for x in picked), flat(p), plane)


def four_bar_anchors(mech: Mechanism, placed: PlacedFourBar) -> dict[str, np.ndarray]:
    """World anchors ``(3,)`` of the joints ``A``-``D`` of ``mech`` (by joint name)
    for the placed four-bar."""
    joints = four_bar_joints(mech)
    order = (joints.A, joints.B, joints.C, joints.D)
    places = (placed.A, placed.B, placed.C, placed.D)
    return {mech.joint_names[j]: placed.world(x) for j, x in zip(order, places)}


def four_bar_design(
    mech: Mechanism, placed: PlacedFourBar, *, tolerance: float = 1e-9
) -> np.ndarray | None:
    """The design vector whose rest anchors are the placed four-bar's (and whose
    coupler point is ``placed.P``, where the file has one), within the design
    bounds; None when the file's design parameters cannot place it (then write
    :func:`four_bar_anchors` instead). Least squares on the design's linear map,
    checked by rebuilding the geometry (``tolerance`` in file units)."""
    want = four_bar_anchors(mech, placed)
    rows = [3 * mech.joint_names.index(name) + k for name in want for k in range(3)]
    target = np.concatenate(list(want.values()))
    p0 = np.asarray(mech.design.p0, dtype=float)
    current = np.asarray(mech.anchors, dtype=float).ravel()[rows]
    matrix = np.asarray(mech.design.matrix)[rows]
    point = four_bar_joints(mech).point
    if point >= 0 and mech.design.points is not None:  # point parameters place P
        block = np.asarray(mech.design.points)[3 * point : 3 * point + 3]
        driven = np.flatnonzero(np.any(block != 0.0, axis=1))
        matrix = np.vstack([matrix, block[driven]])
        target = np.r_[target, placed.world(placed.P)[driven]]
        current = np.r_[current, mech.point_positions[point][driven]]
    change = np.linalg.lstsq(matrix, target - current, rcond=None)[0]
    design = p0 + change
    inside = np.all(design >= mech.design.lower - tolerance) and np.all(
        design <= mech.design.upper + tolerance
    )
    got = read_four_bar(mech, design)
    names = "ABCDP" if four_bar_joints(mech).point >= 0 else "ABCD"
    gaps = [
        np.abs(got.world(getattr(got, n)) - placed.world(getattr(placed, n))).max()
        for n in names
    ]
    return design if inside and max(gaps) <= tolerance else None
