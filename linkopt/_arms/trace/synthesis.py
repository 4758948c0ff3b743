"""Synthesis of a 2- or 3-link planar arm tracing a continuous task (paper 002,
eq. 1-11).

The NLP of eq. 1: minimise ``Σ r_k`` subject to eqs. 2-11 at the critical points
(initial, final, closest, farthest) of every primitive. Decision variables are the base
``s_1`` (eq. 10: inside a base rectangle, as bounds), the link lengths ``r`` and, for 3
links, the absolute angle ``φ_j`` of the static proximal link on each primitive. The
paper also lists the critical states' joint positions as variables tied by the length
equalities of eq. 11; we eliminate them with the closed-form IK (so eq. 11 holds exactly
and the state ``S_{j,u}`` is a function of the variables), and the elbow-consistency
eq. 5 becomes one branch ``σ = ±1`` for the whole task, tried in turn. One branch for
all primitives is also what eq. 5 plus the transitions imply for 2 links (zero mobility
at a transition, Sec. III-F-2a); for 3 links we keep it so that a transition never has
to pass through a stretched distal pair.

Constraints (all ``>= 0``, lengths in task units):

* eq. 2: ``r_{n-1} + r_n - |p_far - s_{n-1}| - m`` and
  ``|p_close - s_{n-1}| - |r_{n-1} - r_n| - m`` with a small margin ``m`` that keeps the
  arm off the singular annulus boundary;
* eqs. 3-4: obstacle discs (grown by Δ/2) clear of SV^over or SV^app
  (:mod:`~linkopt._arms.trace.swept`); for 3 links also of the static proximal link;
* eq. 8: end-effector at ``p_closest`` farther than Δ from the first distal link (the
  paper imposes it when ``r_{n-1} > r_n``; we impose it always: otherwise the same
  distance is the end-effector's distance to the module at ``s_{n-1}``, a collision
  too); eq. 9 (3 links): the primitive (24 samples) farther than Δ from the proximal
  link;
* eqs. 6-7 (3 links): the four-bar at each transition point. Eqs. 6-7 are the law of
  cosines form of "``|P - s_2(θ_1)|`` within the distal annulus" (with
  ``|P - s_2|² = r_g² + r_1² - 2 r_1 r_g cos θ_1`` the bound with ``(r_2 + r_3)²`` is
  the lower one; the paper prints the two bounds of eq. 6 in the other order, and eq. 7
  is the same closure seen from the end-effector); we impose that form at 5 interior
  values of the linear ``θ_1`` motion the verifier will check, together with obstacle
  clearance and self-collision of the links there (the paper leaves these to
  verification; here they are also constraints, which makes verification pass more
  often).

SLSQP (scipy) with exact JAX Jacobians solves each NLP from seeded initial guesses; a
feasible point is accepted only after :func:`~linkopt._arms.trace.verify.verify` passes,
otherwise the next initial guess is tried (Sec. III-E).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass

import jax
import jax.numpy as jnp
import numpy as np
import scipy.optimize
from jaxtyping import Array, Float

from ..._config import jit
from ..._errors import InputError
from .. import checks
from . import geometry as geo
from .settings import TraceSettings
from .swept import BOUNDS, signed_distance, swept_support
from .task import TraceTask
from .verify import PlanarArm, TraceVerification, verify

EQ9_SAMPLES = 24
TRANSITION_SAMPLES = 5
POLISH_ROUNDS = 4


@dataclass(frozen=True)
class TraceResult:
    """Outcome of :func:`synthesize`: the verified design (or ``None``), the stage that
    produced it and one record per NLP solved."""

    task: TraceTask
    design: PlanarArm | None
    verification: TraceVerification | None
    swept: str | None
    seconds: float
    attempts: tuple[dict, ...] = ()

    @property
    def success(self) -> bool:
        return self.design is not None


def unpack(x: Float[Array, " V"], n: int, q: int):
    """``x = [s_1 (2), r (n), φ (q, 3 links only)]`` -> (base, lengths, angles)."""
    phi = x[2 + n :] if n == 3 else jnp.zeros(q)
    return x[:2], x[2 : 2 + n], phi


@dataclass(frozen=True)
class _RowConstants:
    """What the constraint rows of one (task, links, bound) need besides ``x``: margins
    and the smoothing temperature in task units, obstacle centres and radii grown by
    Δ/2 plus the clearance margin."""

    task: TraceTask
    n: int
    kind: str
    margin: float
    temp: float
    delta: float
    centers: Float[Array, "o 2"]
    grown: Float[Array, " o"]


def _row_constants(
    task: TraceTask, n: int, kind: str, settings: TraceSettings
) -> _RowConstants:
    delta = task.link_diameter
    grown = (
        jnp.asarray(task.obstacles[:, 2])
        + delta / 2
        + settings.clearance_margin * task.scale
    )
    return _RowConstants(
        task,
        n,
        kind,
        settings.reach_margin * task.scale,
        settings.smoothing * task.scale,
        delta,
        jnp.asarray(task.obstacles[:, :2]),
        grown,
    )


def _reach_rows(c: _RowConstants, a, b, dmin, dmax):
    """Eq. 2: the distance range to the distal origin inside the reachable annulus."""
    gap = jnp.sqrt((a - b) ** 2 + 1e-12)
    return jnp.stack([a + b - dmax - c.margin, dmin - gap - c.margin])


def _primitive_rows(c: _RowConstants, j: int, base, r, phi, sigma) -> list:
    """Eqs. 2-4, 8 and (3 links) 9 of primitive ``j``."""
    prim, a, b = c.task.primitives[j], r[-2], r[-1]
    origin = geo.distal_origin(base, r, phi[j])
    dmin, dmax = geo.distance_range(prim, origin)
    rows = [_reach_rows(c, a, b, dmin, dmax)]
    supports = (
        swept_support(c.kind, prim, origin, a, b, sigma, c.temp)
        if len(c.centers)
        else []
    )
    for h in supports:
        rows.append(signed_distance(c.centers, h, c.temp) - c.grown)
    close = geo.critical_points(prim, origin)["closest"]
    elbow = geo.ik_elbow(origin, a, b, close, sigma)
    rows.append(jnp.atleast_1d(geo.segment_distance(close, origin, elbow) - c.delta))
    if c.n == 3:
        rows.append(geo.segment_distance(c.centers, base, origin) - c.grown)
        pts = geo.points(prim, jnp.linspace(0.0, 1.0, EQ9_SAMPLES))
        rows.append(geo.segment_distance(pts, base, origin) - c.delta)
    return rows


def _transition_rows(c: _RowConstants, j: int, base, r, phi, sigma) -> list:
    """Eqs. 6-7, obstacle clearance and self-collision at interior samples of the
    transition from primitive ``j`` to ``j + 1`` (3 links)."""
    point = jnp.asarray(c.task.primitives[j].end)
    tau = jnp.linspace(0.0, 1.0, TRANSITION_SAMPLES + 2)[1:-1]
    theta = phi[j] + tau * (phi[j + 1] - phi[j])
    states = jax.vmap(lambda th: geo.arm_states(base, r, th, point[None], sigma)[0])(
        theta
    )
    d = jnp.linalg.norm(point - states[:, 1], axis=-1)
    gap = jnp.sqrt((r[1] - r[2]) ** 2 + 1e-12)
    rows = [r[1] + r[2] - d - c.margin, d - gap - c.margin]
    if len(c.centers):
        segs = geo.segment_distance(
            c.centers[None, None], states[:, :-1, None], states[:, 1:, None]
        )
        rows.append((segs - c.grown).ravel())
    rows.append(
        geo.segment_distance(point, states[:, :-2], states[:, 1:-1]).ravel() - c.delta
    )
    return rows


def constraint_function(
    task: TraceTask, n: int, kind: str, settings: TraceSettings
) -> Callable:
    """``g(x, sigma) -> (m,)``, feasible where every entry is ``>= 0`` (eqs. 2-11)."""
    c = _row_constants(task, n, kind, settings)
    q = len(task.primitives)

    def g(x, sigma):
        base, r, phi = unpack(x, n, q)
        rows = []
        for j in range(q):
            rows += _primitive_rows(c, j, base, r, phi, sigma)
            if n == 3 and j < q - 1:
                rows += _transition_rows(c, j, base, r, phi, sigma)
        return jnp.concatenate([jnp.ravel(v) for v in rows])

    return g


@dataclass(frozen=True)
class Problem:
    g: Callable
    jac: Callable
    violation: Callable
    n: int
    kind: str


def problem_of(g: Callable, n: int, kind: str) -> Problem:
    """The NLP of constraint rows ``g(x, sigma) >= 0``: jitted rows, their Jacobian and
    the squared violation with its gradient."""

    def violation(x, sigma):
        return 0.5 * jnp.sum(jnp.minimum(g(x, sigma), 0.0) ** 2)

    return Problem(
        jit(g),
        jit(jax.jacfwd(g)),
        jit(jax.value_and_grad(violation)),
        n,
        kind,
    )


def build_problem(
    task: TraceTask, n: int, kind: str, settings: TraceSettings
) -> Problem:
    return problem_of(constraint_function(task, n, kind, settings), n, kind)


def _bounds(task: TraceTask, n: int, region: int) -> list[tuple]:
    if len(task.base_regions):
        x0, y0, x1, y1 = task.base_regions[region]
        base = [(x0, x1), (y0, y1)]
    else:
        pts = _path_points(task)
        lo, hi = pts.min(0) - task.scale, pts.max(0) + task.scale
        base = [(lo[0], hi[0]), (lo[1], hi[1])]
    links = [(task.min_link_length, task.max_link_length)] * n
    return base + links + [(None, None)] * (len(task.primitives) if n == 3 else 0)


def _path_points(task: TraceTask, per: int = 64) -> np.ndarray:
    return np.concatenate(
        [geo.points(p, np.linspace(0.0, 1.0, per)) for p in task.primitives]
    )


def initial_guess(
    task: TraceTask, n: int, region: int, rng: np.random.Generator
) -> np.ndarray:
    """A seeded random start: base in its rectangle (or near the path), links sized so
    the farthest path point is just reachable, one proximal angle for all primitives."""
    pts = _path_points(task)
    bounds = _bounds(task, n, region)
    base = np.array([rng.uniform(*bounds[0]), rng.uniform(*bounds[1])])
    x = [base]
    origin = base
    if n == 3:
        towards = pts.mean(0) - base
        phi = np.arctan2(towards[1], towards[0]) + rng.normal(0.0, 0.8)
        far = np.linalg.norm(pts - base, axis=1).max()
        r1 = np.clip(
            rng.uniform(0.2, 0.5) * far, task.min_link_length, task.max_link_length
        )
        origin = base + r1 * np.array([np.cos(phi), np.sin(phi)])
        x.append([r1])
    reach = 1.05 * np.linalg.norm(pts - origin, axis=1).max()
    a = rng.uniform(0.45, 0.65) * reach
    x.append(np.clip([a, reach - a], task.min_link_length, task.max_link_length))
    if n == 3:
        x.append(phi + rng.normal(0.0, 0.05, len(task.primitives)))
    return np.concatenate([np.ravel(v) for v in x])


def _feasible_start(problem: Problem, x0, sigma: int, bounds, settings) -> np.ndarray:
    """Phase 1: L-BFGS-B on the squared constraint violation from ``x0``."""

    def violation(x):
        return tuple(np.asarray(v) for v in problem.violation(x, sigma))

    phase1 = scipy.optimize.minimize(
        violation,
        x0,
        jac=True,
        bounds=bounds,
        method="L-BFGS-B",
        options={"maxiter": settings.max_iterations},
    )
    return np.asarray(phase1.x)


def solve_nlp(
    task: TraceTask,
    problem: Problem,
    x0: np.ndarray,
    sigma: int,
    region: int,
    settings: TraceSettings,
):
    """One solve of eq. 1 from ``x0``; returns (x, feasible, total length).

    As the paper (Sec. III-I), a simpler problem first: L-BFGS-B on the squared
    constraint violation ``½ Σ min(g, 0)²`` finds a feasible neighbourhood, then SLSQP
    minimises ``Σ r_k`` under the constraints from there. SLSQP can stall or leave the
    feasible set on these piecewise-smooth constraints (the swept-area bounds switch
    between critical points), so every feasible iterate is recorded, the lowest-cost one
    is kept and SLSQP is restarted from it (fresh Hessian) up to ``POLISH_ROUNDS``
    times.
    """
    n = problem.n
    bounds = _bounds(task, n, region)

    def g(x):
        return np.asarray(problem.g(x, sigma))

    def cost(x):
        return float(np.sum(x[2 : 2 + n]))

    def grad(x):
        return np.concatenate([np.zeros(2), np.ones(n), np.zeros(len(x) - 2 - n)])

    tol = -settings.feasibility_tol * task.scale
    best = {
        "x": _feasible_start(problem, x0, sigma, bounds, settings),
        "cost": np.inf,
        "feasible": False,
    }

    def keep(x):
        if cost(x) < best["cost"] and g(x).min() >= tol:
            best.update(x=np.array(x), cost=cost(x), feasible=True)

    keep(best["x"])
    cons = {
        "type": "ineq",
        "fun": g,
        "jac": lambda x: np.asarray(problem.jac(x, sigma)),
    }
    _polish(cost, grad, cons, keep, best, bounds, task.scale, settings)
    return best["x"], best["feasible"], cost(best["x"])


def _polish(cost, grad, cons, keep, best: dict, bounds, scale: float, settings) -> None:
    """Phase 2: SLSQP from the best feasible point so far, restarted there (fresh
    Hessian) while it improves, at most ``POLISH_ROUNDS`` times; ``keep`` records."""
    for _ in range(POLISH_ROUNDS):
        before = best["cost"]
        res = scipy.optimize.minimize(
            cost,
            best["x"],
            jac=grad,
            bounds=bounds,
            constraints=[cons],
            callback=keep,
            method="SLSQP",
            options={"maxiter": settings.max_iterations, "ftol": 1e-10},
        )
        keep(res.x)
        if not best["feasible"] or before - best["cost"] <= 1e-6 * scale:
            break


def design_from(x: np.ndarray, n: int, sigma: int, q: int) -> PlanarArm:
    base, r, phi = unpack(np.asarray(x), n, q)
    return PlanarArm(
        np.asarray(base),
        np.asarray(r),
        np.asarray(phi) if n == 3 else np.zeros(0),
        int(sigma),
    )


def check_settings(settings: TraceSettings) -> None:
    """:class:`InputError` for settings the search cannot use (before any work)."""
    checks.count(settings.restarts, "settings: restarts")
    checks.count(settings.best_of, "settings: best_of")
    checks.count(settings.max_iterations, "settings: max_iterations")
    for name in ("reach_margin", "clearance_margin", "smoothing", "feasibility_tol"):
        checks.number(getattr(settings, name), f"settings: {name}", maximum=1.0)
    if not settings.links or any(n not in (2, 3) for n in settings.links):
        raise InputError(f"settings: links: expected 2 and/or 3, got {settings.links}")
    if not settings.swept or any(k not in BOUNDS for k in settings.swept):
        raise InputError(
            f"settings: swept: expected some of {list(BOUNDS)}, got {settings.swept}"
        )


def synthesize(
    task: TraceTask,
    seed: int = 0,
    settings: TraceSettings = TraceSettings(),
    progress: Callable[[str], None] | None = None,
) -> TraceResult:
    """Try 2 links then 3, SV^over then SV^app, ``settings.restarts`` seeded starts each
    (cycling through the base rectangles) and both elbow branches. As the paper, the
    first stage that yields a verified design ends the search; within it the shortest of
    the first ``settings.best_of`` verified designs is returned (default 1: the first,
    which is the paper's feasibility-first rule). ``progress`` receives one line per NLP
    solve. ``seed`` must be a non-negative integer (else :class:`InputError`)."""
    rng = np.random.default_rng(checks.seed(seed))
    check_settings(settings)
    start, attempts = time.perf_counter(), []
    say = progress or (lambda _msg: None)
    for n in settings.links:
        for kind in settings.swept:
            found = _stage(task, n, kind, settings, rng, attempts, say)
            if found:
                design, check = min(found, key=lambda dc: dc[0].lengths.sum())
                seconds = time.perf_counter() - start
                return TraceResult(task, design, check, kind, seconds, tuple(attempts))
    return TraceResult(
        task, None, None, None, time.perf_counter() - start, tuple(attempts)
    )


def _stage(task, n, kind, settings, rng, attempts, say) -> list:
    """One (links, bound) stage: seeded restarts × elbow branches until ``best_of``
    verified designs are found; returns them as (design, verification) pairs."""
    problem = build_problem(task, n, kind, settings)
    found = []
    for restart in range(settings.restarts):
        region = restart % max(1, len(task.base_regions))
        x0 = initial_guess(task, n, region, rng)
        for sigma in (1, -1):
            t0 = time.perf_counter()
            x, feasible, length = solve_nlp(task, problem, x0, sigma, region, settings)
            record = {
                "links": n,
                "swept": kind,
                "restart": restart,
                "sigma": sigma,
                "region": region,
                "feasible": bool(feasible),
                "total_length": length,
                "verified": False,
                "failure": None,
            }
            if feasible:
                design = design_from(x, n, sigma, len(task.primitives))
                check = verify(task, design)
                record.update(
                    verified=check.passed,
                    failure=None if check.passed else check.failures[0],
                )
                if check.passed:
                    found.append((design, check))
            record["seconds"] = time.perf_counter() - t0
            attempts.append(record)
            say(_describe(record))
            if len(found) >= settings.best_of:
                return found
    return found


def _describe(rec: dict) -> str:
    elbow = "up" if rec["sigma"] > 0 else "down"
    head = (
        f"{rec['links']} links, SV^{rec['swept']}, start {rec['restart']}, "
        f"elbow {elbow}:"
    )
    if not rec["feasible"]:
        return f"{head} NLP infeasible ({rec['seconds']:.1f} s)"
    if not rec["verified"]:
        return (
            f"{head} length {rec['total_length']:.4g}, verification failed: "
            f"{rec['failure']} ({rec['seconds']:.1f} s)"
        )
    return f"{head} length {rec['total_length']:.4g}, verified ({rec['seconds']:.1f} s)"
