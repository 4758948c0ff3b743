"""A bounded least-squares polish of a synthesised design, for any mechanism.

The swarm and its capped partial-gradient steps find the basin; near its bottom the
path error is a long, narrow valley that first-order steps cross slowly (the Jansen
leg's foot path: 5.1 → 1.4 cm in 10 gradient iterations, then about 0.01 cm per 5).
A Gauss–Newton step follows such a valley. :func:`polish` minimises, within the
design bounds, the residuals

``r(p) = [d(p),  WEIGHT · max(0, d(p) - MARGIN · tolerance)]``

with ``d(p)`` the distances at the targets (:attr:`.objective.Score.distances`, on
the whole swept cycle, refined to the segments beside the nearest row): the first
half is the RMS error, the second charges a target again where it nears the
tolerance, so that the largest miss, not only the mean, is pulled in. The solver is
SciPy's trust-region reflective ``least_squares``; its Jacobian comes from forward
differences, every column of one evaluation scored in the same batched call as the
point itself (backward where a forward step would leave the bounds), in batches of
the swarm's size, so no new program is compiled.

The polish sees only the distances: whether its design is kept is decided by the
caller on the whole score (singularity, order, collision, feasibility first).
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import least_squares

from .._engine.blocks import in_blocks
from .._engine.model import Mechanism
from .objective import Problem, score

#: Default budget: evaluations of the residuals (each one batched score of the
#: design and its ``D`` difference steps).
EVALUATIONS = 60
#: Fraction of the tolerance from which a target's distance is charged again.
MARGIN = 0.6
#: Weight of that second charge.
WEIGHT = 3.0
#: Forward-difference step, as a fraction of each parameter's range.
STEP = 1e-6


def residuals(distances: np.ndarray, tolerance: float) -> np.ndarray:
    """``r`` of the module docstring for distances ``(..., k)`` -> ``(..., 2k)``;
    a distance that is not finite (a row that did not solve) counts as
    ``100 · tolerance``."""
    d = np.where(np.isfinite(distances), distances, 100.0 * tolerance)
    extra = WEIGHT * np.maximum(0.0, d - MARGIN * tolerance)
    return np.concatenate([d, extra], axis=-1)


def difference_steps(p: np.ndarray, lower: np.ndarray, upper: np.ndarray) -> np.ndarray:
    """Signed difference steps: forward, backward where forward leaves the bounds."""
    h = STEP * np.maximum(upper - lower, 1e-12)
    return np.where(p + h > upper, -h, h)


def _distances(mech, problem: Problem, designs, alpha, batch: int) -> np.ndarray:
    """Distances ``(B, k)`` of ``designs`` scored in blocks of exactly ``batch`` rows
    (:func:`linkopt._engine.blocks.in_blocks`: one compiled score)."""
    return np.asarray(
        in_blocks(
            lambda d: score(mech, problem, d, alpha).distances, [designs], width=batch
        )
    )


def polish(
    mech: Mechanism,
    problem: Problem,
    design,
    alpha: float,
    *,
    batch: int,
    evaluations: int = EVALUATIONS,
) -> np.ndarray:
    """The design that least-squares polishing of ``design`` reaches within the
    design bounds (module docstring), after at most ``evaluations`` evaluations of
    the residuals, each ``ceil((D + 1) / batch)`` batched scores."""
    lower, upper = mech.design.lower, mech.design.upper
    tolerance = problem.targets.tolerance
    x0 = np.clip(np.asarray(design, dtype=float), lower, upper)
    memo: dict[bytes, tuple[np.ndarray, np.ndarray]] = {}

    def evaluate(p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        key = p.tobytes()
        if key not in memo:
            h = difference_steps(p, lower, upper)
            designs = np.vstack([p, p + np.diag(h)])
            r = residuals(_distances(mech, problem, designs, alpha, batch), tolerance)
            memo.clear()
            memo[key] = (r[0], ((r[1:] - r[0]) / h[:, None]).T)
        return memo[key]

    if evaluations < 1 or x0.size == 0:
        return x0
    fit = least_squares(
        lambda p: evaluate(p)[0],
        x0,
        jac=lambda p: evaluate(p)[1],
        bounds=(lower, upper),
        method="trf",
        max_nfev=evaluations,
    )
    return np.clip(fit.x, lower, upper)
