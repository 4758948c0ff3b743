"""Solving the co-design program (:mod:`.nlp`) from many starts: SLSQP from each
seeded start, in spawned processes where asked, and the best solution.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import jax.numpy as jnp
import numpy as np
import scipy.optimize

from .. import checks
from .nlp import FEASIBLE_TOL, OBJECTIVE_SCALE, Problem, evaluate, objective_parts


@dataclass(frozen=True)
class ArmSolution:
    """One SLSQP run: ``theta (n_W, n)``, ``design (m,)``, feasibility and costs."""

    theta: np.ndarray
    design: np.ndarray
    objective: float
    parts: dict
    max_violation: float
    feasible: bool
    iterations: int
    seconds: float
    message: str
    start: int = -1


def initial_point(problem: Problem, seed: int) -> np.ndarray:
    """A random seed point (module docstring), from ``np.random.default_rng(seed)``."""
    rng = np.random.default_rng(checks.seed(seed))
    arm = problem.arm
    d = rng.uniform(arm.lower, arm.upper)
    at_targets = rng.uniform(
        -np.pi, np.pi, (len(problem.target_waypoints), arm.num_joints)
    )
    steps = np.arange(problem.num_waypoints)
    theta = np.stack(
        [
            np.interp(steps, problem.target_waypoints, at_targets[:, j])
            for j in range(arm.num_joints)
        ],
        axis=1,
    )
    return np.concatenate([theta.ravel(), d])


def solve_from(
    problem: Problem,
    z0: np.ndarray,
    *,
    max_iterations: int | None = None,
    start: int = -1,
) -> ArmSolution:
    """One SLSQP solve of eq. 1 from ``z0``."""
    arm = problem.arm
    iterations = max_iterations or problem.task.solver["max_iterations"]
    cache: dict = {}

    def at(z):
        key = z.tobytes()
        if key not in cache:
            cache.clear()
            cache[key] = evaluate(problem, z)
        return cache[key]

    scale = OBJECTIVE_SCALE
    bounds = [(None, None)] * (problem.num_waypoints * arm.num_joints) + list(
        zip(arm.lower, arm.upper)
    )
    started = time.perf_counter()
    result = scipy.optimize.minimize(
        lambda z: (at(z)[0] * scale, at(z)[1] * scale),
        np.asarray(z0, dtype=float),
        jac=True,
        method="SLSQP",
        bounds=bounds,
        constraints=[
            {"type": "ineq", "fun": lambda z: -at(z)[2], "jac": lambda z: -at(z)[3]}
        ],
        options={"maxiter": iterations, "ftol": 1e-6},
    )
    return finish(
        problem,
        result.x,
        time.perf_counter() - started,
        int(result.nit),
        str(result.message),
        start,
    )


def finish(
    problem: Problem,
    z,
    seconds: float = 0.0,
    iterations: int = 0,
    message: str = "",
    start: int = -1,
) -> ArmSolution:
    """Evaluate a point: objective, its parts, max constraint value."""
    z = np.asarray(z, dtype=float)
    _, _, g, _ = evaluate(problem, z)
    parts = {k: float(v) for k, v in objective_parts(problem, jnp.asarray(z)).items()}
    w = problem.task.weights
    violation = float(np.max(g)) if g.size else 0.0
    theta, d = problem.split(z)
    return ArmSolution(
        theta.copy(),
        d.copy(),
        sum(w[k] * v for k, v in parts.items()),
        parts,
        violation,
        violation <= FEASIBLE_TOL,
        iterations,
        seconds,
        message,
        start,
    )


def best_of(solutions: list[ArmSolution]) -> ArmSolution:
    """The feasible solution of least objective, else the least infeasible one."""
    feasible = [s for s in solutions if s.feasible]
    if feasible:
        return min(feasible, key=lambda s: s.objective)
    return min(solutions, key=lambda s: s.max_violation)


def _solve_start(job) -> ArmSolution:
    problem, seed, start = job
    return solve_from(problem, initial_point(problem, seed), start=start)


def solve(
    problem: Problem,
    *,
    starts: int | None = None,
    seed: int | None = None,
    workers: int = 1,
    progress=None,
) -> tuple[ArmSolution, list[ArmSolution]]:
    """Multi-start solve: start ``k`` uses seed ``seed + k``; returns (best, all).

    ``starts`` and ``seed`` default to the task's ``[solver]`` values; ``starts`` and
    ``workers`` must be at least 1 and ``seed`` non-negative (else :class:`InputError`).

    With ``workers > 1`` the starts run in that many spawned processes (each one core:
    see :mod:`linkopt._config`); results do not depend on the worker count.
    """
    starts = checks.count(
        problem.task.solver["starts"] if starts is None else starts, "starts"
    )
    seed = checks.seed(problem.task.solver["seed"] if seed is None else seed, "seed")
    workers = checks.count(workers, "workers")
    jobs = [(problem, seed + k, k) for k in range(starts)]
    if workers <= 1:
        results = []
        for job in jobs:
            results.append(_solve_start(job))
            if progress:
                progress(results[-1])
    else:
        import concurrent.futures
        import multiprocessing

        from ..._cache import requested
        from ..._config import adopt

        with concurrent.futures.ProcessPoolExecutor(
            workers,
            mp_context=multiprocessing.get_context("spawn"),
            initializer=adopt,
            initargs=(requested(),),
        ) as pool:
            results = []
            for solution in pool.map(_solve_start, jobs):
                results.append(solution)
                if progress:
                    progress(solution)
    return best_of(results), results
