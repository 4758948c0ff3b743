"""Start designs of a planar four-bar path synthesis, from closed forms (numpy, before
any sweep).

A precision-point synthesis is not one design: the four-bars whose coupler curve meets
``k`` points form a family (four points leave four free parameters of the eight a file
with free pivots and pins has). This module samples it. The seeds are refined together
by Levenberg–Marquardt (numpy, batched over the seeds, forward-difference Jacobians,
the design kept in its box) in the file's own design space, with one crank angle per
target as extra unknowns, on

* the coupler point's miss at each target: ``P(p, φ_j) − x_j``, ``P`` from the
  closed form of the four-bar (the crank turned by ``φ_j`` about ``A``, the pin ``C``
  the intersection of the circles about ``B`` and ``D`` on the rest pose's branch, the
  coupler turned with ``B → C``), and
* each miss beyond ``HINGE`` of the tolerance once more (``HINGE_WEIGHT``): the misses
  are evened out below the tolerance rather than one left above it;
* the transmission angle's shortfall: ``w · max(0, μ_req − μ_worst(p))``, ``μ_worst``
  the closed form over the full crank turn (:func:`.fourbar.transmission`, zero for a
  four-bar whose crank cannot turn fully), ``w`` ten times the targets' extent, so
  that a degree short costs more than any tolerance.

The seeds: the file's design, the precision-point fits of :func:`.fourbar.fit_path`
(many seeds; at most five of the targets each, evenly spread or drawn), for more than
five targets the four-bars of :mod:`.atlas` whose coupler curves best match the
targets' shape, each carried into the design space by least squares on the joint
anchors (and the coupler point's driven coordinates), and designs drawn uniformly in
the design box. A design's coupler point follows the file's rule (the point's
``follow``, :func:`linkopt._engine.following.follow`, and the point parameters that
place it, :func:`linkopt._engine.following.drive`), so every start is a design of the
file: where point parameters let the coupler point move, its place on the coupler is
part of every fit (the fits' coupler point carried into the design with the pins) and
of the refinement's unknowns. :func:`candidates` returns the refined designs; the
synthesis run scores them all with the dense cycle in one batched call and seeds
its swarm with the best (:mod:`.run`).

Applies to a path target without timing on a one-motor planar four-bar
(:func:`.fourbar.four_bar_joints`) whose named point is on the coupler, with a linear
design map (no link angles); :func:`applies` says whether.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from .._engine.following import rest_points
from .._engine.model import Mechanism
from .._errors import InputError
from . import atlas, fourbar
from .targets import Targets

#: Levenberg–Marquardt iterations of the refinement (all starts together).
ITERATIONS = 150
#: Degrees added to the asked transmission angle by the refinement (a margin
#: against the dense sweep's sampling).
MARGIN_DEG = 0.5
#: Samples of the crank turn for the first guess of each target's crank angle.
SAMPLES = 72
#: Weight of a target's miss beyond ``HINGE`` of the tolerance (on top of the miss
#: itself): the refinement evens the misses out below the tolerance.
HINGE, HINGE_WEIGHT = 0.6, 3.0
#: Weight of a radian of transmission shortfall, in the targets' extents.
SHORTFALL_WEIGHT = 10.0
#: Targets above this many (beyond precision points) also get :mod:`.atlas` starts.
ATLAS_FROM = 5
#: How closely the fast rule of the coupler point must reproduce the file's
#: ``follow`` (file units) on random designs to be used.
RULE_CHECK = 1e-9


@dataclass(frozen=True)
class Frame:
    """What the closed form needs of a file: the four-bar's joint indices, the plane
    (rows origin, e1, e2), the linear design map of the joints' anchors, and the rule
    by which the coupler point follows the design (``"driven"``: point parameters
    (``kind = "point"``) place it, ``w0 + pmap @ (p - p0)``; ``"line"``: a fixed
    affine coordinate ``lam`` along ``B → C`` and a fixed offset ``h`` to its left;
    ``"fixed"``: it does not move; ``"follow"``: the file's rule, one design at a
    time)."""

    joints: fourbar.FourBarJoints
    plane: np.ndarray  # (3, 3)
    flat0: np.ndarray  # (3J,) the file design's anchors
    matrix: np.ndarray  # (3J, n_p)
    p0: np.ndarray
    point: int
    rule: str = "follow"
    lam: float = 0.0
    h: float = 0.0
    #: ``(3, n_p)`` the rows of the point parameters' map for the coupler point (zero
    #: where none drives it) and its rest position at the file's design.
    pmap: np.ndarray | None = None
    w0: np.ndarray | None = None


def applies(mech: Mechanism, targets: Targets) -> bool:
    """Whether closed-form starts apply (module docstring)."""
    if targets.kind != "path" or targets.motors is not None:
        return False
    if mech.design.turns is not None or mech.design.size == 0:
        return False
    try:
        joints = fourbar.four_bar_joints(mech, targets.name)
    except InputError:
        return False
    return int(mech.point_bodies[joints.point]) == joints.coupler


def frame_of(mech: Mechanism, targets: Targets) -> Frame:
    """The :class:`Frame` of a file (:func:`applies` true), its point rule checked
    against the file's ``follow`` on random designs of the box (seed 0)."""
    joints = fourbar.four_bar_joints(mech, targets.name)
    placed0 = fourbar.read_four_bar(mech, None, targets.name)
    size = 3 * mech.anchors.shape[0]
    point = mech.point_names.index(targets.name)
    base = Frame(
        joints,
        placed0.plane,
        np.ravel(mech.anchors).astype(float),
        np.asarray(mech.design.matrix, dtype=float)[:size],
        np.asarray(mech.design.p0, dtype=float),
        point,
        pmap=_point_map(mech, point),
        w0=np.asarray(mech.point_positions[point], dtype=float),
    )
    rest = _followed(mech, base, base.p0[None])[0]
    _, b, c, _, p = rest
    along = c - b
    lam = float(np.dot(p - b, along) / np.dot(along, along))
    h = float(_cross(along, p - b) / np.linalg.norm(along))
    rng = np.random.default_rng(0)
    trial = rng.uniform(mech.design.lower, mech.design.upper, (3, base.p0.size))
    truth = _followed(mech, base, trial)
    for rule in ("driven", "line", "fixed"):
        frame = replace(base, rule=rule, lam=lam, h=h)
        if np.max(np.abs(placed_batch(mech, frame, trial) - truth)) <= RULE_CHECK:
            return frame
    return base


def _point_map(mech: Mechanism, point: int) -> np.ndarray:
    """``(3, n_p)``: the point parameters' map rows of ``point`` (zeros where no
    parameter drives it)."""
    if mech.design.points is None:
        return np.zeros((3, mech.design.size))
    return np.asarray(mech.design.points, dtype=float)[3 * point : 3 * point + 3]


def _plane_of(frame: Frame, world):
    return (world - frame.plane[0]) @ frame.plane[1:].T


def _anchors(frame: Frame, designs):
    """Plane coordinates ``(N, 4, 2)`` of ``A, B, C, D`` at rest."""
    flat = frame.flat0 + (designs - frame.p0) @ frame.matrix.T
    anchors = flat.reshape(len(designs), -1, 3)
    j = frame.joints
    return _plane_of(frame, anchors[:, [j.A, j.B, j.C, j.D]])


def _followed(mech: Mechanism, frame: Frame, designs) -> np.ndarray:
    """``(N, 5, 2)`` by the file's own rule (:func:`follow`), one design at a time."""
    out = []
    for design in designs:
        anchors = (frame.flat0 + frame.matrix @ (design - frame.p0)).reshape(-1, 3)
        points = rest_points(mech, anchors, design - frame.p0)
        world = np.vstack([anchors[[frame.joints.A, frame.joints.B, frame.joints.C,
                                    frame.joints.D]], points[frame.point]])  # fmt: skip
        out.append(_plane_of(frame, world))
    return np.stack(out)


def placed_batch(mech: Mechanism, frame: Frame, designs) -> np.ndarray:
    """Plane coordinates ``(N, 5, 2)`` of ``A, B, C, D, P`` at the rest pose of
    designs ``(N, n_p)``."""
    designs = np.atleast_2d(np.asarray(designs, dtype=float))
    if frame.rule == "follow":
        return _followed(mech, frame, designs)
    four = _anchors(frame, designs)
    if frame.rule == "driven":
        point = _plane_of(frame, frame.w0 + (designs - frame.p0) @ frame.pmap.T)
    elif frame.rule == "fixed":
        point = np.broadcast_to(
            _followed(mech, frame, frame.p0[None])[0, 4], (len(designs), 2)
        )
    else:
        b, c = four[:, 1], four[:, 2]
        along = c - b
        unit = along / np.linalg.norm(along, axis=1, keepdims=True)
        left = np.stack([-unit[:, 1], unit[:, 0]], 1)
        point = b + frame.lam * along + frame.h * left
    return np.concatenate([four, point[:, None]], axis=1)


def placed(mech: Mechanism, frame: Frame, design: np.ndarray) -> np.ndarray:
    """Plane coordinates ``(5, 2)`` of ``A, B, C, D, P`` at the rest pose of
    ``design``."""
    return placed_batch(mech, frame, design[None])[0]


def _cross(u, v):
    return u[..., 0] * v[..., 1] - u[..., 1] * v[..., 0]


def _turn(v, angle):
    c, s = np.cos(angle), np.sin(angle)
    return np.stack([c * v[..., 0] - s * v[..., 1], s * v[..., 0] + c * v[..., 1]], -1)


def coupler_batch(rest: np.ndarray, phi: np.ndarray) -> np.ndarray:
    """The coupler point ``(N, m, 2)`` of four-bars at rest ``rest`` (``(N, 5, 2)``:
    A, B, C, D, P) with the crank turned by ``phi`` ``(N, m)`` from rest, on the rest
    pose's branch. Where the circles do not meet, the nearest (clipped) pose:
    continuous in its arguments, for the least squares."""
    a, b0, c0, d, p0 = (rest[:, i, None, :] for i in range(5))
    b = a + _turn(np.broadcast_to(b0 - a, phi.shape + (2,)), phi)
    coupler = np.linalg.norm(c0 - b0, axis=-1)
    rocker = np.linalg.norm(c0 - d, axis=-1)
    branch = np.sign(_cross(d - b0, c0 - b0))
    branch = np.where(branch == 0, 1.0, branch)
    to_d = d - b
    gap = np.maximum(np.linalg.norm(to_d, axis=-1), 1e-300)
    cosine = (coupler**2 + gap**2 - rocker**2) / (2 * coupler * gap + 1e-300)
    angle = branch * np.arccos(np.clip(cosine, -1.0, 1.0))
    c = b + coupler[..., None] * _turn(to_d / gap[..., None], angle)
    u = np.broadcast_to(c0 - b0, c.shape)
    turned = np.arctan2(_cross(u, c - b), np.sum(u * (c - b), axis=-1))
    return b + _turn(np.broadcast_to(p0 - b0, c.shape), turned)


def coupler_points(rest: np.ndarray, phi: np.ndarray) -> np.ndarray:
    """:func:`coupler_batch` of one four-bar ``(5, 2)`` at angles ``(m,)``."""
    return coupler_batch(rest[None], np.asarray(phi, dtype=float)[None])[0]


def worst_batch(rest: np.ndarray) -> np.ndarray:
    """The closed-form least transmission angle over the full turn (rad, ``(N,)``):
    :func:`.fourbar.transmission` of each four-bar."""
    a, b, c, d = (
        np.linalg.norm(rest[:, i] - rest[:, j], axis=-1)
        for i, j in ((1, 0), (2, 1), (2, 3), (3, 0))
    )
    bc = 2 * b * c + 1e-300
    near = np.arccos(np.clip((b * b + c * c - (d - a) ** 2) / bc, -1, 1))
    far = np.arccos(np.clip((b * b + c * c - (d + a) ** 2) / bc, -1, 1))
    return np.minimum(near, np.pi - far)


def worst_transmission(rest: np.ndarray) -> float:
    """:func:`worst_batch` of one four-bar ``(5, 2)``."""
    return float(worst_batch(rest[None])[0])


@dataclass(frozen=True)
class Problem:
    """A refinement's fixed data: the frame, the targets in the plane ``(k, 2)``,
    the transmission bound (rad), the tolerance, the weight of a transmission
    shortfall (the targets' extent) and the design box."""

    frame: Frame
    goals: np.ndarray
    need: float
    tolerance: float
    weight: float
    lower: np.ndarray
    upper: np.ndarray


def _residuals(mech, problem: Problem, x):
    """Residuals ``(N, 3k + 1)`` of variables ``x`` ``(N, n_p + k)``: the misses,
    their hinges beyond ``HINGE`` of the tolerance, the transmission shortfall."""
    n = problem.frame.p0.size
    rest = placed_batch(mech, problem.frame, x[:, :n])
    miss = coupler_batch(rest, x[:, n:]) - problem.goals[None]
    size = np.sqrt(np.sum(miss**2, axis=-1) + 1e-300)
    hinge = HINGE_WEIGHT * np.maximum(size - HINGE * problem.tolerance, 0.0)
    short = np.maximum(problem.need - worst_batch(rest), 0.0) if problem.need else 0.0
    short = problem.weight * np.broadcast_to(short, (len(x),))
    return np.concatenate([miss.reshape(len(x), -1), hinge, short[:, None]], axis=1)


def first_angles(rest: np.ndarray, goals: np.ndarray) -> np.ndarray:
    """Each target's crank angle ``(N, k)`` guessed from the nearest of ``SAMPLES``
    poses of each four-bar ``(N, 5, 2)``."""
    phi = np.linspace(-np.pi, np.pi, SAMPLES, endpoint=False)
    curve = coupler_batch(rest, np.broadcast_to(phi, (len(rest), SAMPLES)))
    gaps = np.linalg.norm(curve[:, :, None] - goals[None, None], axis=-1)
    return phi[np.argmin(gaps, axis=1)]


def refine_batch(mech: Mechanism, problem: Problem, designs) -> tuple:
    """Designs ``(N, n_p)`` refined together (module docstring) by
    Levenberg–Marquardt, forward-difference Jacobians, the design kept in its box:
    the refined designs and their residual norms ``(N,)``."""
    lower, upper = problem.lower, problem.upper
    designs = np.clip(np.atleast_2d(np.asarray(designs, dtype=float)), lower, upper)
    n = designs.shape[1]
    rest = placed_batch(mech, problem.frame, designs)
    x = np.concatenate([designs, first_angles(rest, problem.goals)], axis=1)
    low = np.r_[lower, np.full(len(problem.goals), -np.inf)]
    high = np.r_[upper, np.full(len(problem.goals), np.inf)]
    width = np.r_[upper - lower, np.full(len(problem.goals), 2 * np.pi)]
    step = 1e-7 * np.maximum(width, 1e-12)
    damping = np.full(len(x), 1e-3)
    r = _residuals(mech, problem, x)
    cost = np.sum(r**2, axis=1)
    eye = np.eye(x.shape[1])
    for _ in range(ITERATIONS):
        moved = x[:, None, :] + eye[None] * step[None, None, :]
        flat = _residuals(mech, problem, moved.reshape(-1, x.shape[1]))
        jac = (flat.reshape(len(x), x.shape[1], -1) - r[:, None, :]) / step[
            None, :, None
        ]
        normal = jac @ np.swapaxes(jac, 1, 2)  # (N, v, v) = JᵀJ
        grad = jac @ r[:, :, None]
        scaled = normal + damping[:, None, None] * (
            np.einsum("nii->ni", normal)[:, :, None] * eye + 1e-12 * eye
        )
        delta = -np.linalg.solve(scaled, grad)[..., 0]
        trial = np.clip(x + delta, low, high)
        r_trial = _residuals(mech, problem, trial)
        c_trial = np.sum(r_trial**2, axis=1)
        better = c_trial < cost
        x = np.where(better[:, None], trial, x)
        r = np.where(better[:, None], r_trial, r)
        cost = np.where(better, c_trial, cost)
        damping = np.clip(np.where(better, damping / 3.0, damping * 4.0), 1e-12, 1e8)
    return x[:, :n], np.sqrt(cost)


def problem_of(
    mech: Mechanism,
    targets: Targets,
    min_transmission_deg: float,
    full_turn: bool = True,
):
    """The :class:`Problem` of refining ``mech``'s designs towards ``targets``. The
    transmission bound is over the full crank turn, so it applies where the crank
    turns fully (``full_turn``: a closed curve, or an open one of a motor without
    limits); over a limited motor span the cycle's score alone judges it."""
    frame = frame_of(mech, targets)
    goals = _plane_of(frame, targets.values[:, :3])
    asked = min_transmission_deg > 0 and full_turn
    need = np.radians(min_transmission_deg + MARGIN_DEG) if asked else 0.0
    weight = SHORTFALL_WEIGHT * float(np.linalg.norm(np.ptp(goals, axis=0)))
    d = mech.design
    return Problem(frame, goals, need, targets.tolerance, weight, d.lower, d.upper)


def _carried(frame: Frame, rest: np.ndarray) -> np.ndarray:
    """Four-bars ``(N, 5, 2)`` (``A, B, C, D, P`` in the plane) carried into the
    design space: least squares on the anchors of ``A``-``D`` and the coordinates of
    ``P`` that point parameters drive."""
    j = frame.joints
    rows = [3 * i + m for i in (j.A, j.B, j.C, j.D) for m in range(3)]
    driven = np.flatnonzero(np.any(frame.pmap != 0.0, axis=1))  # the point's, if any
    matrix = np.vstack([frame.matrix[rows], frame.pmap[driven]])
    flat0 = np.concatenate([frame.flat0[rows], frame.w0[driven]])
    world = frame.plane[0] + rest @ frame.plane[1:]  # (N, 5, 3)
    want = np.concatenate([world[:, :4].reshape(len(rest), -1),
                           world[:, 4][:, driven]], axis=1)  # fmt: skip
    change = np.linalg.lstsq(matrix, (want - flat0).T, rcond=None)[0]
    return frame.p0 + change.T


def _atlas_designs(frame: Frame, goals, closed: bool, need, seed: int, count: int):
    """The best :func:`.atlas.matches` of the targets' shape, carried into the
    design space."""
    if count <= 0:
        return []
    return list(_carried(frame, atlas.matches(goals, closed, need, seed, count)))


def _fit_designs(frame: Frame, goals, closed: bool, seed: int, count: int):
    """Precision-point fits (:func:`.fourbar.fit_path`) on at most five targets,
    carried into the design space (:func:`_carried`)."""
    rng = np.random.default_rng(seed)
    k = len(goals)
    out = []
    for attempt in range(count):
        if k <= 5:
            chosen = np.arange(k)
        elif attempt % 2 == 0:
            offset = rng.integers(0, max(1, k // 5))
            chosen = np.unique(np.round(np.linspace(offset, k - 1, 5)).astype(int))
        else:
            chosen = np.sort(rng.choice(k, 5, replace=False))
        try:
            fit = fourbar.fit_path(
                goals[chosen], seed=int(rng.integers(1 << 31)), closed=closed, starts=2
            )
        except (InputError, ValueError, np.linalg.LinAlgError):
            continue
        p = fit.placed
        out.append(_carried(frame, np.stack([p.A, p.B, p.C, p.D, p.P])[None])[0])
    return out


def candidates(
    mech: Mechanism,
    targets: Targets,
    *,
    seed: int,
    count: int = 32,
    min_transmission_deg: float = 0.0,
    fits: int | None = None,
    full_turn: bool = True,
) -> np.ndarray:
    """``(C, n_p)`` refined start designs (module docstring), those that keep the
    transmission bound first, then by least residual;
    ``count`` seeds: the file's design, ``fits`` precision-point fits (default a
    quarter of ``count``) and designs drawn uniformly in the box (``seed``)."""
    problem = problem_of(mech, targets, min_transmission_deg, full_turn)
    rng = np.random.default_rng(seed)
    fits = count // 4 if fits is None else fits
    seeds = [problem.frame.p0]
    seeds += _fit_designs(problem.frame, problem.goals, targets.closed, seed, fits)
    if len(targets.values) > ATLAS_FROM:
        seeds += _atlas_designs(
            problem.frame, problem.goals, targets.closed, problem.need, seed, count // 2
        )
    drawn = rng.uniform(problem.lower, problem.upper, (max(0, count - len(seeds)),
                                                       problem.lower.size))  # fmt: skip
    seeds = np.vstack([np.stack(seeds)[:count], drawn])
    refined, norms = refine_batch(mech, problem, seeds)
    short = problem.need - worst_batch(placed_batch(mech, problem.frame, refined)) > 0
    return refined[np.lexsort((norms, short))]
