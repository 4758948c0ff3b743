"""Dense motor-space and end-effector-space maps by continuation (for plots and checks).

A regular grid is solved in breadth-first waves from the cell nearest the rest pose:
each wave takes the unsolved cells next to solved ones and solves them all in one
batched call, each warm-started from a solved neighbour, so the map shows the rest
assembly branch and not a mix of branches. A cell is feasible when its solve converged
and its state stayed within ``MAX_JUMP`` (homogenised, max-norm) of the neighbour it
started from; otherwise it is infeasible (NaN in the maps). Python iterates over waves
(about twice the grid side), never over cells.

A wave of any size is solved in blocks of a fixed number of cells
(:mod:`linkopt._engine.blocks`), so every map, section and verification grid of a
mechanism runs the same compiled FK or BK program, where a program per padded wave size
would compile four to five per map, each taking seconds
(``benchmarks/bench_compile.py`` lists a command's compilations).

Three motors and outputs are drawn as 2-D sections, each solved in its own plane from
seeds on a coarse 3-D grid (:func:`sections`), not as one fine 3-D
grid; the plots' default resolution depends on the number of outputs
(:data:`PLOT_RESOLUTION`). With ``[collision]`` enabled each map also holds its
cells' least clearance between the checked links (:func:`least_clearance`). A
``progress`` callback gets each wave's count of visited cells (library code never
prints; the CLI does).

Budget: a grid's cost grows as its side to the power of its dimension, so callers check
it before anything is allocated (:func:`grid_cost`, :func:`check_budget`;
:func:`check_plot_resolution` for the plots' maps, and
:func:`linkopt._design.verify.check_resolution` for ``verify``). The limits,
:data:`MAX_CELLS` and :data:`MAX_BYTES` (half of the machine's memory, read at run
time).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from numbers import Integral

import numpy as np

from .._engine.collision import clearance, has_collision
from .._engine.constraints import constraint_rows
from .._engine.kinematics import solve_bk, solve_fk
from .._engine.model import Mechanism
from .._engine.readout import motor_values, output_values, reported_values
from .._engine.singularity import f_sing
from .._errors import InputError
from .settings import MAX_BYTES, MAX_CELLS

MAX_JUMP = 0.25

#: Solve time per cell, seconds, at state size 35 (scaled by (size / 35)²), for the
#: estimate a grid is refused on (the measurement: docs/performance.md).
SECONDS_PER_CELL = 5e-3
#: Python's overhead per visited cell: a dict entry, its tuple key and a state view.
CELL_OVERHEAD = 400


@dataclass(frozen=True)
class GridCost:
    """An estimate of one continuation grid, made before it is allocated."""

    cells: int
    bytes: int  # peak memory
    seconds: float  # on one core


def check_count(value, where: str, minimum: int) -> int:
    """``value`` as an int, when it is a whole number (not a bool) ≥ ``minimum``."""
    if isinstance(value, bool) or not isinstance(value, Integral):
        raise InputError(
            f"{where}: expected a whole number >= {minimum}, got {value!r}"
        )
    if value < minimum:
        raise InputError(f"{where}: expected at least {minimum}, got {value}")
    return int(value)


def grid_cost(
    mech: Mechanism, shape: tuple[int, ...], read_cells: int, grids=1
) -> GridCost:
    """Cost of :func:`continuation_grid` over ``shape`` (``grids`` of them, one after
    the other), then σ_min of ``read_cells`` states in one batch.

    Memory: per cell the inputs, the state, the status and the parent's state
    (``CELL_OVERHEAD`` for the Python objects); per cell of a wave the solver's
    Jacobian and normal equations; per state read both Jacobians and four n × n
    factors each. Time: ``SECONDS_PER_CELL`` scaled by (n / 35)².
    """
    cells = math.prod(int(v) for v in shape)
    n = mech.state_size
    rows = max(constraint_rows(mech)[k] for k in ("fk", "bk"))
    wave = 2 * len(shape) * cells // max(shape)  # a wave, generously
    per_cell = 8 * (2 * len(shape) + 2 * n + 1) + CELL_OVERHEAD
    solving = 8 * wave * (3 * rows * n + 4 * n * n)
    reading = 8 * read_cells * 2 * (rows * n + 5 * n * n)
    seconds = grids * cells * SECONDS_PER_CELL * (n / 35) ** 2
    return GridCost(cells, cells * per_cell + max(solving, reading), seconds)


def _duration(seconds: float) -> str:
    for unit, size in (("days", 86400), ("h", 3600), ("min", 60)):
        if seconds >= size:
            return f"{seconds / size:.3g} {unit}"
    return f"{seconds:.2g} s"


def check_budget(
    cost: GridCost,
    what: str,
    *,
    max_cells: int = MAX_CELLS,
    max_bytes: int = MAX_BYTES,
    raise_with: str = "max_cells",
) -> None:
    """:class:`InputError` naming ``what`` and the estimate when ``cost`` exceeds the
    cell or memory limit (``raise_with``: what raises the cell limit)."""
    if cost.cells <= max_cells and cost.bytes <= max_bytes:
        return
    over = (
        f"the limit of {max_cells} cells (raise it with {raise_with})"
        if cost.cells > max_cells
        else f"the memory limit of {max_bytes / 2**30:.3g} GiB"
    )
    raise InputError(
        f"{what}: {cost.cells:.4g} grid cells, estimated {cost.bytes / 2**30:.3g} GiB "
        f"of memory and {_duration(cost.seconds)} on one core; over {over}"
    )


#: Steps of the third axis of :func:`sections` (its ``depth``), and the most cells on
#: that axis (the steps, three cuts and the start value).
SECTION_DEPTH = 9
SECTION_CELLS = SECTION_DEPTH + 4
#: In-plane values per axis of the coarse grid that seeds the sections (the start
#: value adds one).
SECTION_SEED = 9
#: Default cells per axis of the plots' maps, by the number of motors and outputs: a
#: three-output figure has six small panels (three rows of sections), so 40² cells each
#: (3 · 40² = 4800 a space, with the coarse seed grid 5300) draw as finely as the
#: two-output figure's two 60² maps (3600 each).
PLOT_RESOLUTION = {2: 60, 3: 40}


def plot_resolution(mech: Mechanism, resolution=None) -> int:
    """``resolution``, or the default for the mechanism's number of outputs
    (:data:`PLOT_RESOLUTION`; 60 for any other count)."""
    if resolution is None:
        return PLOT_RESOLUTION.get(mech.num_outputs, 60)
    return resolution


def plot_cost(mech: Mechanism, resolution: int) -> GridCost:
    """The cost of the plots' maps: two ``resolution²`` grids for two motors and
    outputs; for three, per space a coarse seed grid and three ``resolution²``
    sections (:func:`sections`). ``cells`` is the largest grid's."""
    if mech.num_motors != 3:
        return grid_cost(mech, (resolution, resolution), resolution**2, 2)
    seed = (SECTION_SEED + 1, SECTION_SEED + 1, SECTION_CELLS)
    plane = grid_cost(mech, (resolution, resolution), resolution**2, 6)
    coarse = grid_cost(mech, seed, 0, 2)
    return GridCost(
        max(plane.cells, coarse.cells),
        max(plane.bytes, coarse.bytes),
        plane.seconds + coarse.seconds,
    )


def check_plot_resolution(
    mech: Mechanism,
    resolution,
    *,
    where: str = "resolution",
    max_cells: int = MAX_CELLS,
    max_bytes: int = MAX_BYTES,
    raise_with: str = "max_cells",
) -> int:
    """The plots' maps (:func:`linkopt._draw.space_plots.plot_spaces`) at
    ``resolution`` cells per axis (``None``: :func:`plot_resolution`'s default):
    :class:`InputError` before any work when it is not a whole number ≥ 2 or a grid is
    over budget (:func:`check_budget`, :func:`plot_cost`)."""
    resolution = check_count(plot_resolution(mech, resolution), where, 2)
    check_budget(
        plot_cost(mech, resolution),
        f"{where}: {resolution} cells per axis",
        max_cells=max_cells,
        max_bytes=max_bytes,
        raise_with=raise_with,
    )
    return resolution


@dataclass(frozen=True)
class Map2D:
    """A solved 2-D grid: ``values[i, j]`` at ``(axis0[i], axis1[j])``; NaN =
    infeasible."""

    axis0: np.ndarray  # (N,)
    axis1: np.ndarray  # (N,)
    f_sing: np.ndarray  # (N, N)
    motors: np.ndarray  # (N, N, M)
    outputs: np.ndarray  # (N, N, K)
    feasible: np.ndarray  # (N, N) bool
    reported: np.ndarray | None = (
        None  # (N, N, E) reported outputs; None: the file has none
    )
    #: (N, N) least clearance between checked links (file units,
    #: :func:`least_clearance`); None: the file checks no collisions
    clearance: np.ndarray | None = None


def _neighbours(cell: tuple[int, ...], shape: tuple[int, ...]):
    for axis in range(len(shape)):
        for step in (-1, 1):
            n = list(cell)
            n[axis] += step
            if 0 <= n[axis] < shape[axis]:
                yield tuple(n)


def continuation_grid(
    solve,
    values: np.ndarray,
    start_cell: tuple[int, ...] | None,
    start_state: np.ndarray | None,
    *,
    seeds: dict | None = None,
    progress: Callable[[int, int], None] | None = None,
):
    """Breadth-first continuation over a grid of input values ``grid_shape + (D,)``.

    ``solve(inputs (n, D), starts (n, S))`` is a batched solver; returns the states and
    a feasibility mask over the grid. The first wave solves ``start_cell`` from
    ``start_state`` and each of ``seeds`` (``{cell: state}``, more starts, e.g. from a
    coarser grid: :func:`sections`) from its state. ``progress(visited, cells)`` is
    called after each wave.
    """
    shape = values.shape[:-1]
    parent_state = dict(seeds or {})
    if start_cell is not None:
        parent_state[tuple(start_cell)] = np.asarray(start_state)
    size_s = next(iter(parent_state.values())).shape
    states = np.zeros(shape + size_s)
    status = np.zeros(shape, dtype=int)  # 0 unvisited, 1 solved, -1 failed
    frontier = list(parent_state)
    total = math.prod(shape)
    while frontier:
        cells = np.array(frontier)
        index = tuple(cells.T)
        starts = np.stack([parent_state[tuple(c)] for c in cells])
        sol = solve(values[index], starts)
        new_states = np.asarray(sol.state)
        ok = np.asarray(sol.converged) & (
            np.max(np.abs(new_states - starts), axis=1) <= MAX_JUMP
        )
        status[index] = np.where(ok, 1, -1)
        states[index] = new_states
        frontier = []
        for k in np.flatnonzero(ok):
            for n in _neighbours(tuple(int(v) for v in cells[k]), shape):
                if status[n] == 0 and n not in parent_state:
                    parent_state[n] = new_states[k]
                    frontier.append(n)
        if progress is not None:
            progress(int(np.count_nonzero(status)), total)
    return states, status == 1


def grid_axes(low, high, resolution):
    resolution = check_count(resolution, "resolution", 2)
    return [np.linspace(lo, hi, resolution) for lo, hi in zip(low, high)]


def finish_map(mech, axes, states, feasible, design) -> Map2D:
    """The map of a solved grid: ``f_sing`` and the read-outs of its feasible cells
    (each a batched call over those cells only: a map's unreached and failed cells,
    a sixth of the five-bar's, are NaN whatever they would read), NaN elsewhere."""
    reached = states[feasible]
    sing = _on_cells(feasible, reached, lambda s: f_sing(mech, s, design=design), ())
    read = [
        _on_cells(feasible, reached, lambda s, f=f: f(mech, s, design=design), (n,))
        for f, n in (
            (motor_values, mech.num_motors),
            (output_values, mech.num_outputs),
            (reported_values, mech.reported_table.size),
        )
    ]
    return Map2D(
        axes[0],
        axes[1],
        sing,
        read[0],
        read[1],
        feasible,
        read[2] if mech.reported_table.size else None,  # a read-out: no solve
        least_clearance(mech, states, feasible, design),
    )


def _on_cells(feasible, reached, read, tail: tuple[int, ...]) -> np.ndarray:
    """``read(reached)`` (one row per feasible cell) placed on the grid, NaN in the
    other cells; no call when no cell is feasible or a row has no values."""
    out = np.full(feasible.shape + tail, np.nan)
    if len(reached) and math.prod(tail):
        out[feasible] = np.asarray(read(reached))
    return out


def least_clearance(mech: Mechanism, states, feasible, design) -> np.ndarray | None:
    """Per cell, the least clearance between the checked links in its state (file
    units, :func:`linkopt._engine.collision.clearance`; NaN where infeasible, ``inf``
    with no pair checked); None without ``[collision]`` enabled. A read-out of the
    map's solved states, no solve; only the feasible cells are read."""
    if not has_collision(mech):
        return None
    least = np.full(feasible.shape, np.nan)
    least[feasible] = clearance(mech, states[feasible], design=design).minimum
    return least


def merged_values(low: float, high: float, steps: int, extra) -> np.ndarray:
    """``steps`` even values over ``[low, high]`` merged with the ``extra`` values."""
    return np.unique(
        np.concatenate([np.linspace(low, high, steps), np.asarray(extra, float)])
    )


def sections(
    mech: Mechanism,
    kind: str,
    low,
    high,
    resolution: int,
    cuts,
    *,
    start_state,
    start_values,
    design=None,
    depth: int = SECTION_DEPTH,
    progress: Callable[[dict], None] | None = None,
) -> list[Map2D]:
    """2-D sections of a 3-D motor (``kind="fk"``) or output (``"bk"``) space at the
    given values ``cuts`` of the third variable.

    Each section is a ``resolution²`` continuation in its own plane, seeded from every
    reached cell of that plane in one coarse 3-D continuation grid
    (``SECTION_SEED²`` in-plane values and ``depth`` on the third axis, each merged with
    the start value, the third also with the cuts): a section shows the start state's
    assembly branch, reached through the third dimension, and not a branch found by a
    fresh solve at the cut. Instead of a fine grid of ``resolution² × depth`` cells,
    most of which would never be drawn, this solves ``3 resolution²`` cells plus the
    coarse ``SECTION_SEED² · depth`` (``benchmarks/bench_outputs.py --old`` times
    both). What may differ: a part of a section that the branch reaches through the
    third dimension only between two coarse cells is not drawn (our choice, for the
    time).
    ``progress`` gets ``{"stage", "cells", "of"}`` after each wave.
    """
    if len(low) != 3 or len(high) != 3 or len(start_values) != 3:
        raise InputError(
            "sections: low, high and start_values need three values each (three "
            f"motors or outputs), got {len(low)}, {len(high)} and {len(start_values)}"
        )
    resolution = check_count(resolution, "resolution", 2)
    coarse = [
        merged_values(low[i], high[i], SECTION_SEED, [start_values[i]])
        for i in range(2)
    ]
    coarse.append(merged_values(low[2], high[2], depth, [*cuts, start_values[2]]))
    report = _stage(progress, f"{kind.upper()} sections: coarse 3-D grid")
    coarse_states, coarse_ok = solve_grid(
        mech, kind, coarse, start_values, start_state, design, report
    )
    fine = grid_axes(low[:2], high[:2], resolution)
    out = []
    for number, cut in enumerate(cuts):
        k = int(np.argmin(np.abs(coarse[2] - cut)))
        seeds = _seeds(coarse, fine, coarse_states[:, :, k], coarse_ok[:, :, k])
        report = _stage(progress, f"{kind.upper()} section {number + 1} of {len(cuts)}")
        states, feasible = _plane(mech, kind, fine, coarse[2][k], seeds, design, report)
        out.append(finish_map(mech, fine, states, feasible, design))
    return out


def _stage(progress, stage: str):
    """``progress`` as a ``(visited, cells)`` callback of :func:`continuation_grid`."""
    if progress is None:
        return None
    return lambda done, total: progress({"stage": stage, "cells": done, "of": total})


def _seeds(coarse, fine, states: np.ndarray, ok: np.ndarray) -> dict:
    """The reached cells of one coarse plane as seeds of the fine plane: each at the
    fine cell nearest to it (the coarse in-plane values lie inside the fine axes)."""
    nearest = [
        np.argmin(np.abs(f[:, None] - c[None, :]), axis=0)
        for c, f in zip(coarse[:2], fine)
    ]
    return {
        (int(nearest[0][a]), int(nearest[1][b])): states[a, b]
        for a, b in zip(*np.nonzero(ok))
    }


def _plane(mech: Mechanism, kind: str, fine, third: float, seeds, design, report):
    """Continuation over the ``fine`` plane at ``third`` from ``seeds`` (none: all
    infeasible)."""
    n0, n1 = len(fine[0]), len(fine[1])
    if not seeds:
        return np.full((n0, n1, mech.state_size), np.nan), np.zeros((n0, n1), bool)
    grid = np.meshgrid(*fine, indexing="ij")
    values = np.stack([*grid, np.full_like(grid[0], third)], axis=-1)
    solver = solve_fk if kind == "fk" else solve_bk

    def solve(v, s):
        return solver(mech, v, start=s, design=design)

    return continuation_grid(solve, values, None, None, seeds=seeds, progress=report)


def solve_grid(
    mech: Mechanism,
    kind: str,
    axes,
    start_values,
    start_state,
    design,
    progress=None,
):
    """Continuation over the grid spanned by ``axes``, from the cell nearest
    ``start_values``."""
    values = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1)
    cell = tuple(int(np.argmin(np.abs(ax - v))) for ax, v in zip(axes, start_values))
    solver = solve_fk if kind == "fk" else solve_bk

    def solve(v, s):
        return solver(mech, v, start=s, design=design)

    return continuation_grid(
        solve,
        values,
        cell,
        np.asarray(start_state),
        progress=progress,
    )


def motor_map(
    mech: Mechanism,
    low,
    high,
    resolution: int,
    *,
    start_state,
    start_motors,
    design=None,
    progress: Callable[[dict], None] | None = None,
) -> Map2D:
    """FK over a motor-space box ``[low, high]`` (2 motors), from a solved start
    state."""
    axes = grid_axes(low, high, resolution)
    report = _stage(progress, "motor space")
    states, feasible = solve_grid(
        mech, "fk", axes, start_motors, start_state, design, report
    )
    return finish_map(mech, axes, states, feasible, design)


def output_map(
    mech: Mechanism,
    low,
    high,
    resolution: int,
    *,
    start_state,
    start_outputs,
    design=None,
    progress: Callable[[dict], None] | None = None,
) -> Map2D:
    """BK over an end-effector-space box ``[low, high]`` (2 outputs), from a solved
    start state."""
    axes = grid_axes(low, high, resolution)
    report = _stage(progress, "output space")
    states, feasible = solve_grid(
        mech, "bk", axes, start_outputs, start_state, design, report
    )
    return finish_map(mech, axes, states, feasible, design)
