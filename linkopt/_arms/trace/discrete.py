"""The discretised approach the paper compares against (paper 002, Sec. IV-B, Fig. 6).

The path is replaced by ``n`` points equidistant in arc length (the paper: 25), and a
2-link arm is synthesised that reaches every point with its links clear of the obstacles
and one elbow branch for all points (the paper's elbow-consistency constraint), with the
same objective as ours (total link length; the paper's re-implementation of [6] adds a
state-smoothness cost, which we leave out — it does not change which points are
reached). Nothing constrains the arm between the points, which is the point of the
comparison: :func:`compare` then measures where the continuous curve leaves that
design's reachable annulus and runs the continuous verifier on it.
"""

from __future__ import annotations

from dataclasses import dataclass

import jax.numpy as jnp
import numpy as np
from jaxtyping import Float

from .. import checks
from . import geometry as geo
from .synthesis import Problem, TraceSettings, initial_guess, problem_of, solve_nlp
from .task import TraceTask
from .verify import PlanarArm, TraceVerification, verify


@dataclass(frozen=True)
class DiscreteComparison:
    """``points``: the ``n`` targets; ``curve``: dense path points; ``outside``: which
    of them lie outside the design's annulus; ``excursion``: the largest distance
    outside."""

    design: PlanarArm
    points: Float[np.ndarray, "n 2"]
    curve: Float[np.ndarray, "N 2"]
    outside: np.ndarray
    excursion: float
    fraction_outside: float
    verification: TraceVerification


def equidistant_points(
    task: TraceTask, n: int, dense: int = 4000
) -> Float[np.ndarray, "n 2"]:
    """``n`` points at equal arc length along the whole path (first and last
    included)."""
    curve = dense_curve(task, dense)
    s = np.concatenate(
        [[0.0], np.cumsum(np.linalg.norm(np.diff(curve, axis=0), axis=1))]
    )
    want = np.linspace(0.0, s[-1], n)
    return np.stack([np.interp(want, s, curve[:, i]) for i in range(2)], axis=1)


def dense_curve(task: TraceTask, total: int = 4000) -> Float[np.ndarray, "N 2"]:
    lengths = np.array([p.length for p in task.primitives])
    counts = np.maximum(16, (total * lengths / lengths.sum()).astype(int))
    return np.concatenate(
        [
            geo.points(p, np.linspace(0.0, 1.0, c))
            for p, c in zip(task.primitives, counts)
        ]
    )


def _point_problem(task: TraceTask, pts: np.ndarray) -> Problem:
    centers = jnp.asarray(task.obstacles[:, :2])
    grown = jnp.asarray(task.obstacles[:, 2]) + task.link_diameter / 2
    p = jnp.asarray(pts)

    def g(x, sigma):
        base, r = x[:2], x[2:4]
        d = jnp.linalg.norm(p - base, axis=1)
        rows = [r[0] + r[1] - d, d - jnp.sqrt((r[0] - r[1]) ** 2 + 1e-12)]
        states = geo.arm_states(base, r, 0.0, p, sigma)
        if len(centers):
            segs = geo.segment_distance(
                centers[None, None], states[:, :-1, None], states[:, 1:, None]
            )
            rows.append((segs - grown).ravel())
        rows.append(
            geo.segment_distance(p, states[:, 0], states[:, 1]) - task.link_diameter
        )
        return jnp.concatenate(rows)

    return problem_of(g, 2, "points")


def discretised_design(
    task: TraceTask, n: int = 25, seed: int = 0, restarts: int = 6
) -> PlanarArm | None:
    """Shortest 2-link arm found that reaches the ``n`` points collision-free (see
    module)."""
    rng = np.random.default_rng(checks.seed(seed))
    problem = _point_problem(task, equidistant_points(task, n))
    settings = TraceSettings()
    best = None
    for restart in range(restarts):
        region = restart % max(1, len(task.base_regions))
        x0 = initial_guess(task, 2, region, rng)
        for sigma in (1, -1):
            x, feasible, length = solve_nlp(task, problem, x0, sigma, region, settings)
            if feasible and (best is None or length < best[1]):
                best = (
                    PlanarArm(x[:2].copy(), x[2:4].copy(), np.zeros(0), sigma),
                    length,
                )
    return None if best is None else best[0]


def compare(task: TraceTask, design: PlanarArm, n: int = 25) -> DiscreteComparison:
    """Where the continuous path leaves the annulus of ``design`` (eq. 2), and the
    continuous verification of ``design`` on the whole path."""
    curve = dense_curve(task)
    a, b = design.lengths
    d = np.linalg.norm(curve - design.base, axis=1)
    beyond = np.maximum(d - (a + b), abs(a - b) - d)
    seg = np.linalg.norm(np.diff(curve, axis=0), axis=1)
    outside = beyond > 0
    frac = float(seg[outside[1:] | outside[:-1]].sum() / seg.sum())
    return DiscreteComparison(
        design,
        equidistant_points(task, n),
        curve,
        outside,
        float(max(beyond.max(), 0.0)),
        frac,
        verify(task, design),
    )
