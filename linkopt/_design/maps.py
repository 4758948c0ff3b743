"""Dense motor-space and end-effector-space maps by continuation (for plots and checks).

A regular grid is solved in breadth-first waves from the cell nearest the rest pose:
each wave takes the unsolved cells next to solved ones and solves them all in one
batched call, each warm-started from a solved neighbour, so the map shows the rest
assembly branch and not a mix of branches. A cell is feasible when its solve converged
and its state stayed within ``MAX_JUMP`` (homogenised, max-norm) of the neighbour it
started from; otherwise it is infeasible (NaN in the maps). Python iterates over waves
(about twice the grid side), never over cells.

A wave is padded to ``chunk · 2^k`` cells, the fewest that hold it, so few batch shapes
are compiled and a wave of more than ``chunk`` cells never costs twice its size. The
plots' maps use ``chunk`` = the grid side: a 2-D wave holds at most about twice that
many cells, where waves padded to multiples of four grid sides made the plots slower
for the same pixels.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from .._engine.kinematics import solve_bk, solve_fk
from .._engine.model import Mechanism
from .._engine.readout import motor_values, output_values
from .._engine.singularity import f_sing

MAX_JUMP = 0.25


class Map2D(NamedTuple):
    """A solved 2-D grid: ``values[i, j]`` at ``(axis0[i], axis1[j])``; NaN =
    infeasible."""

    axis0: np.ndarray  # (N,)
    axis1: np.ndarray  # (N,)
    f_sing: np.ndarray  # (N, N)
    motors: np.ndarray  # (N, N, M)
    outputs: np.ndarray  # (N, N, K)
    feasible: np.ndarray  # (N, N) bool


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
    start_cell: tuple[int, ...],
    start_state: np.ndarray,
    chunk: int,
):
    """Breadth-first continuation over a grid of input values ``grid_shape + (D,)``.

    ``solve(inputs (n, D), starts (n, S))`` is a batched solver; returns the states and
    a feasibility mask over the grid.
    """
    shape = values.shape[:-1]
    states = np.zeros(shape + start_state.shape)
    status = np.zeros(shape, dtype=int)  # 0 unvisited, 1 solved, -1 failed
    parent_state = {start_cell: start_state}
    frontier = [start_cell]
    while frontier:
        cells = np.array(frontier)
        index = tuple(cells.T)
        starts = np.stack([parent_state[tuple(c)] for c in cells])
        inputs = values[index]
        size = chunk
        while size < len(cells):
            size *= 2
        padded = size - len(cells)
        sol = solve(
            np.concatenate([inputs, np.repeat(inputs[-1:], padded, 0)]),
            np.concatenate([starts, np.repeat(starts[-1:], padded, 0)]),
        )
        new_states = np.asarray(sol.state)[: len(cells)]
        ok = np.asarray(sol.converged)[: len(cells)] & (
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
    return states, status == 1


def _axes(low, high, resolution):
    return [np.linspace(lo, hi, resolution) for lo, hi in zip(low, high)]


def _finish(mech, axes, states, feasible, design) -> Map2D:
    flat = states.reshape(-1, states.shape[-1])
    shape = feasible.shape
    fs = np.asarray(f_sing(mech, flat, design=design)).reshape(shape)
    motors = np.asarray(motor_values(mech, flat, design=design)).reshape(shape + (-1,))
    outputs = np.asarray(output_values(mech, flat, design=design)).reshape(
        shape + (-1,)
    )
    nan = np.where(feasible, 1.0, np.nan)
    return Map2D(
        axes[0],
        axes[1],
        fs * nan,
        motors * nan[..., None],
        outputs * nan[..., None],
        feasible,
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
    depth: int = 9,
) -> list[Map2D]:
    """2-D sections of a 3-D motor (``kind="fk"``) or output (``"bk"``) space at the
    given values ``cuts`` of the third variable.

    One 3-D continuation grid is solved (``resolution² × n3`` cells, the third axis
    ``depth`` even steps over ``[low[2], high[2]]`` merged with the cuts and the start
    value), so every section shows the start state's assembly branch, reached through
    the third dimension, and not a branch found by a fresh solve at the cut.
    """
    if len(low) != 3:
        raise ValueError("sections need exactly three motors or outputs")
    third = np.unique(
        np.concatenate(
            [
                np.linspace(low[2], high[2], depth),
                np.asarray(cuts, float),
                [start_values[2]],
            ]
        )
    )
    axes = _axes(low[:2], high[:2], resolution) + [third]
    states, feasible = _solve_from(mech, kind, axes, start_values, start_state, design)
    out = []
    for cut in cuts:
        k = int(np.argmin(np.abs(third - cut)))
        out.append(_finish(mech, axes, states[:, :, k], feasible[:, :, k], design))
    return out


def _solve_from(mech: Mechanism, kind: str, axes, start_values, start_state, design):
    """Continuation over the grid spanned by ``axes``, from the cell nearest
    ``start_values``."""
    values = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1)
    cell = tuple(int(np.argmin(np.abs(ax - v))) for ax, v in zip(axes, start_values))
    solver = solve_fk if kind == "fk" else solve_bk

    def solve(v, s):
        return solver(mech, v, start=s, design=design)

    return continuation_grid(
        solve, values, cell, np.asarray(start_state), chunk=len(axes[0])
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
) -> Map2D:
    """FK over a motor-space box ``[low, high]`` (2 motors), from a solved start
    state."""
    axes = _axes(low, high, resolution)
    states, feasible = _solve_from(mech, "fk", axes, start_motors, start_state, design)
    return _finish(mech, axes, states, feasible, design)


def output_map(
    mech: Mechanism,
    low,
    high,
    resolution: int,
    *,
    start_state,
    start_outputs,
    design=None,
) -> Map2D:
    """BK over an end-effector-space box ``[low, high]`` (2 outputs), from a solved
    start state."""
    axes = _axes(low, high, resolution)
    states, feasible = _solve_from(mech, "bk", axes, start_outputs, start_state, design)
    return _finish(mech, axes, states, feasible, design)
