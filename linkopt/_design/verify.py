"""Dense verification of a design over its whole target range (beyond the paper).

The paper's sparse samples carry no guarantee (its Sec. VII). Here the target box is
gridded (``resolution`` points per output) and solved by backward-kinematics
continuation from the rest pose (:func:`linkopt._design.maps.continuation_grid`,
batched). A design passes when every cell is reached on the rest branch (coverage 1) and
every cell has ``f_sing < α₋``, the threshold below which the culled metric is zero.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from .._engine.geometry import rest_state
from .._engine.kinematics import solve_bk, solve_bk_path
from .._engine.model import Mechanism
from .._engine.readout import output_values
from .._engine.singularity import singular_values
from .evaluation import alpha_minus
from .maps import continuation_grid

ENTRY_STEPS = 40


class Verification(NamedTuple):
    passed: bool
    coverage: float  # fraction of grid cells reached on the rest branch
    cells: int
    threshold: float  # α₋
    max_f_sing: float  # over reached cells
    min_sigma_fk: float
    min_sigma_bk: float
    worst_outputs: np.ndarray  # (K,) cell with the largest f_sing (file units)
    unreached_example: np.ndarray | None  # (K,) one unreached cell, if any
    grid_shape: tuple[int, ...]


def _entry_state(mech: Mechanism, design, box_point: np.ndarray):
    """Bring the rest pose into the box along a straight output path (continuation)."""
    rest = rest_state(mech)
    start = np.asarray(output_values(mech, rest, design=design))
    path = start + np.linspace(0.0, 1.0, ENTRY_STEPS)[:, None] * (box_point - start)
    solution = solve_bk_path(mech, path, start=rest, design=design)
    return np.asarray(solution.state[-1]), bool(np.all(np.asarray(solution.converged)))


def verify(mech: Mechanism, design=None, resolution: int | None = None) -> Verification:
    """Grid the target range and check coverage and singularity distance (see module
    doc)."""
    k = mech.num_outputs
    resolution = resolution or (41 if k <= 2 else 13)
    axes = [
        np.linspace(lo, hi, resolution)
        for lo, hi in zip(mech.output_min, mech.output_max)
    ]
    values = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1)
    rest_out = np.asarray(output_values(mech, rest_state(mech), design=design))
    cell = tuple(int(np.argmin(np.abs(ax - v))) for ax, v in zip(axes, rest_out))
    state, entered = _entry_state(mech, design, values[cell])
    shape = values.shape[:-1]
    if entered:

        def solve(v, s):
            return solve_bk(mech, v, start=s, design=design)

        states, feasible = continuation_grid(
            solve, values, cell, state, chunk=max(64, 2 * resolution ** max(k - 1, 1))
        )
    else:
        states, feasible = np.zeros(shape + state.shape), np.zeros(shape, dtype=bool)
    threshold = alpha_minus(mech)
    reached = values[feasible]
    if len(reached):
        sigmas = np.asarray(singular_values(mech, states[feasible], design=design))
        f = np.sum(1.0 / sigmas, axis=1)
        worst = reached[int(np.argmax(f))]
        max_f, min_fk, min_bk = (
            float(np.max(f)),
            float(np.min(sigmas[:, 0])),
            float(np.min(sigmas[:, 1])),
        )
    else:
        worst, max_f, min_fk, min_bk = np.full(k, np.nan), float("inf"), 0.0, 0.0
    coverage = float(np.mean(feasible))
    missing = values[~feasible]
    return Verification(
        passed=coverage == 1.0 and max_f < threshold,
        coverage=coverage,
        cells=int(feasible.size),
        threshold=threshold,
        max_f_sing=max_f,
        min_sigma_fk=min_fk,
        min_sigma_bk=min_bk,
        worst_outputs=worst,
        unreached_example=missing[0] if len(missing) else None,
        grid_shape=shape,
    )
