"""Dense verification of a design over its whole target range (beyond the paper).

The paper's sparse samples carry no guarantee (its Sec. VII). Here the target box is
gridded (``resolution`` points per output) and solved by backward-kinematics
continuation from the rest pose (:func:`linkopt._design.maps.continuation_grid`,
batched). A design passes when every cell is reached on the rest branch (coverage 1) and
every cell has ``f_sing < α₋``, the threshold below which the culled metric is zero.
A file with ``[collision]`` enabled must also keep every pair of checked links at
least the clearance apart in every reached cell (:mod:`linkopt._engine.collision`);
the result then names the closest pair and its cell. A file with motor limits
(``[[motors]]`` ``min``/``max``) must keep every motor within them in every reached
cell: the result names the motor that goes furthest beyond (or comes closest to) its
limits, its value and its cell (:func:`limit_check`).

A grid of ``resolution^K`` cells is costed before it is allocated
(:func:`check_resolution`, against :data:`linkopt._design.maps.MAX_CELLS` and
``MAX_BYTES``); a caller about to start a long run calls it first, so a resolution that
verification would refuse fails at once.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .._engine.arguments import check_design
from .._engine.collision import clearance, has_collision, pair_names
from .._engine.geometry import rest_state
from .._engine.kinematics import solve_bk, solve_bk_path
from .._engine.mobility import check_design_mobility
from .._engine.model import Mechanism
from .._engine.readout import motor_values, output_values
from .._engine.singularity import singular_values
from .evaluation import alpha_minus
from .maps import (
    MAX_BYTES,
    MAX_CELLS,
    check_budget,
    check_count,
    continuation_grid,
    grid_cost,
)

ENTRY_STEPS = 40


@dataclass(frozen=True)
class Verification:
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
    #: With ``[collision]`` enabled (else None): the least clearance over the reached
    #: cells (file units), its body pair, and its cell (output values, file units).
    min_clearance: float | None = None
    collision_pair: tuple[str, str] | None = None
    collision_outputs: np.ndarray | None = None
    #: With motor limits (else None): the motor that goes furthest beyond its limits
    #: over the reached cells (or, when none does, comes closest to one), its value
    #: (rad or file units), its cell (output values, file units) and by how much it is
    #: beyond (negative: the margin left), in the motor's units.
    limit_motor: str | None = None
    limit_value: float | None = None
    limit_outputs: np.ndarray | None = None
    limit_excess: float | None = None

    def as_json(self) -> dict:
        """The fields as JSON-ready values (arrays and the grid shape as lists), as
        ``verification.json`` and a run's verification rounds hold them; the collision
        fields only when the file checks collisions, the limit fields only when it has
        motor limits."""
        return {
            k: (np.asarray(v).tolist() if isinstance(v, (np.ndarray, tuple)) else v)
            for k, v in vars(self).items()
            if (k not in COLLISION_FIELDS or self.min_clearance is not None)
            and (k not in LIMIT_FIELDS or self.limit_excess is not None)
        }

    @property
    def beyond_limits(self) -> bool:
        """Whether a reached cell needs a motor beyond its limits."""
        return self.limit_excess is not None and self.limit_excess > 0.0


#: The :class:`Verification` fields of a file with ``[collision]`` enabled.
COLLISION_FIELDS = ("min_clearance", "collision_pair", "collision_outputs")
#: The :class:`Verification` fields of a file with motor limits.
LIMIT_FIELDS = ("limit_motor", "limit_value", "limit_outputs", "limit_excess")
#: How far (homogenised: rad, or reference lengths) a motor may stand past its limit
#: and still count as within it: a cell on the limit is solved to the LM tolerance.
LIMIT_SLACK = 1e-9


def limit_check(
    mech: Mechanism, states: np.ndarray, feasible: np.ndarray, reached, design
) -> dict:
    """The motor-limit fields of a verification (:class:`Verification`): over the
    reached cells, the motor whose value lies furthest beyond its limits, compared in
    homogenised units (rad, reference lengths), with its value and cell; the excess is
    zero within :data:`LIMIT_SLACK`. ``limit_excess`` -inf when no cell was reached;
    empty without motor limits."""
    if not mech.motor_limited:
        return {}
    flat = states.reshape(-1, states.shape[-1])[feasible.reshape(-1)]
    if not len(flat):
        return {"limit_excess": float("-inf")}
    motors = np.asarray(motor_values(mech, flat, design=design))
    beyond = np.maximum(motors - mech.motor_max, mech.motor_min - motors)
    scaled = beyond / mech.motor_scale
    cell, motor = np.unravel_index(int(np.argmax(scaled)), scaled.shape)
    excess = float(beyond[cell, motor])
    if 0.0 < scaled[cell, motor] <= LIMIT_SLACK:
        excess = 0.0
    return {
        "limit_motor": mech.motor_names[motor],
        "limit_value": float(motors[cell, motor]),
        "limit_outputs": reached[cell],
        "limit_excess": excess,
    }


def collision_check(
    mech: Mechanism, states: np.ndarray, feasible: np.ndarray, reached, design
) -> dict:
    """The collision fields of a verification: the least clearance over the reached
    cells, its pair and cell (``inf``, None, None when no cell was reached or no pair
    is checked); empty without ``[collision]`` enabled."""
    if not has_collision(mech):
        return {}
    flat = states.reshape(-1, states.shape[-1])[feasible.reshape(-1)]
    result = clearance(mech, flat, design=design)
    if not len(flat) or result.worst[0] < 0:
        return {"min_clearance": float("inf")}
    cell = int(np.argmin(result.minimum))
    return {
        "min_clearance": float(result.minimum[cell]),
        "collision_pair": pair_names(mech, result.worst[cell]),
        "collision_outputs": reached[cell],
    }


def _entry_state(mech: Mechanism, design, box_point: np.ndarray):
    """Bring the rest pose into the box along a straight output path (continuation)."""
    rest = rest_state(mech)
    start = np.asarray(output_values(mech, rest, design=design))
    path = start + np.linspace(0.0, 1.0, ENTRY_STEPS)[:, None] * (box_point - start)
    solution = solve_bk_path(mech, path, start=rest, design=design)
    return np.asarray(solution.state[-1]), bool(np.all(np.asarray(solution.converged)))


#: Cells a default grid of four or more outputs may have (13³ = 2197 for three).
HIGH_DIMENSIONAL_CELLS = 20_000


def default_resolution(mech: Mechanism) -> int:
    """Grid points per output when none is given: 41 for up to two outputs, 13 for
    three, and beyond that the finest grid of at most :data:`HIGH_DIMENSIONAL_CELLS`
    cells (11 for four outputs, 7 for five, 5 for six) whose estimated memory is within
    :data:`~linkopt._design.maps.MAX_BYTES` (a Stewart platform's 98-number state makes
    that 4 for its six outputs), never coarser than 3. A careful engineer's compromise:
    the paper verifies only 2-D maps, and a 6-D grid at 13 points per axis would be 4.8
    million BK continuations."""
    k = mech.num_outputs
    if k <= 2:
        return 41
    if k == 3:
        return 13
    resolution = 3
    while (resolution + 1) ** k <= HIGH_DIMENSIONAL_CELLS:
        resolution += 1
    while resolution > 3 and _cost(mech, resolution).bytes > MAX_BYTES:
        resolution -= 1
    return resolution


def _cost(mech: Mechanism, resolution: int):
    """The estimated cost of a verification grid (:func:`~.maps.grid_cost`)."""
    k = mech.num_outputs
    return grid_cost(mech, (resolution,) * k, resolution**k)


def check_resolution(
    mech: Mechanism,
    resolution: int | None = None,
    *,
    max_cells: int = MAX_CELLS,
    max_bytes: int = MAX_BYTES,
    where: str = "resolution",
    raise_with: str = "max_cells",
) -> int:
    """The resolution :func:`verify` uses (``None``: :func:`default_resolution`);
    :class:`~linkopt.InputError` naming ``where`` before any work when it is not a
    whole number ≥ 2, or when the grid's estimated cells or memory exceed the limits
    (the message gives the estimate, the limit and ``raise_with``, what raises it)."""
    if resolution is None:
        resolution = default_resolution(mech)
    resolution = check_count(resolution, where, 2)
    k = mech.num_outputs
    cost = _cost(mech, resolution)
    check_budget(
        cost,
        f"{where}: {resolution} points per output ({k} outputs)",
        max_cells=max_cells,
        max_bytes=max_bytes,
        raise_with=raise_with,
    )
    return resolution


def reached_sigmas(
    mech: Mechanism, states: np.ndarray, feasible: np.ndarray, design
) -> np.ndarray:
    """``(σ_min^FK, σ_min^BK)`` of the reached cells ``(R, 2)``, in grid order
    (batched in fixed blocks, :mod:`linkopt._engine.blocks`: one compiled program
    whatever the count of reached cells)."""
    flat = states.reshape(-1, states.shape[-1])
    return np.asarray(singular_values(mech, flat[feasible.reshape(-1)], design=design))


def verify(
    mech: Mechanism,
    design=None,
    resolution: int | None = None,
    *,
    max_cells: int = MAX_CELLS,
    max_bytes: int = MAX_BYTES,
) -> Verification:
    """Grid the target range and check coverage and singularity distance (see module
    doc); ``resolution`` and the limits are checked first (:func:`check_resolution`)."""
    check_design(mech, design)
    if design is not None:
        check_design_mobility(mech, design, "design")
    resolution = check_resolution(
        mech, resolution, max_cells=max_cells, max_bytes=max_bytes
    )
    k = mech.num_outputs
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

        states, feasible = continuation_grid(solve, values, cell, state)
    else:
        states, feasible = np.zeros(shape + state.shape), np.zeros(shape, dtype=bool)
    threshold = alpha_minus(mech)
    reached = values[feasible]
    if len(reached):
        sigmas = reached_sigmas(mech, states, feasible, design)
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
    collision = collision_check(mech, states, feasible, reached, design)
    clear = collision.get("min_clearance", np.inf) >= _band(mech)
    limits = limit_check(mech, states, feasible, reached, design)
    kept = limits.get("limit_excess", -np.inf) <= 0.0
    return Verification(
        passed=coverage == 1.0 and max_f < threshold and clear and kept,
        coverage=coverage,
        cells=int(feasible.size),
        threshold=threshold,
        max_f_sing=max_f,
        min_sigma_fk=min_fk,
        min_sigma_bk=min_bk,
        worst_outputs=worst,
        unreached_example=missing[0] if len(missing) else None,
        grid_shape=shape,
        **collision,
        **limits,
    )


def _band(mech: Mechanism) -> float:
    """The clearance a verified design keeps (file units; 0 without collisions)."""
    return mech.collision.clearance if has_collision(mech) else 0.0
