"""The configurations a browser view moves through: FK over a regular motor grid,
solved by continuation from the rest pose (:func:`linkopt._design.maps.solve_grid`),
with ``f_sing`` and the least clearance of every reached cell.

A cell the continuation does not reach on the rest pose's branch is failed (its state
is not kept, and a page shows it as failed, never a neighbour's or an interpolated
one). The grid spans each motor's limits where the file gives them, else
``±ANGLE_SPAN`` rad about rest for a revolute motor (``±π`` for a mechanism of one
motor: a whole turn of a crank) and ``±LINEAR_SPAN`` reference lengths for a linear
one, narrower where the grid is coarse (:data:`MAX_ANGLE_STEP`,
:data:`MAX_LINEAR_STEP`).

Budget: the page holds every reached state, so its size, not the solve, bounds the
grid: :data:`MAX_DATA_BYTES` of numbers over all the designs of a page
(:func:`check_view_grid`; :func:`default_resolution` picks the finest grid within it).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from jaxtyping import Bool, Float

from .._engine.geometry import rest_state
from .._engine.model import Mechanism
from .._engine.singularity import f_sing
from .._engine.welding import parts
from .._errors import InputError
from .maps import check_count, grid_cost, least_clearance, solve_grid

#: Half-width of a revolute motor's grid without limits (rad), and of a linear one
#: (reference lengths).
ANGLE_SPAN = math.pi / 3
LINEAR_SPAN = 0.25
#: The largest step between two cells without motor limits: a revolute motor's (rad),
#: a linear one's (reference lengths). A coarse grid spans less (the Stewart
#: platform's three cells per leg: ±0.05 reference lengths), so that neighbouring
#: cells stay on one branch (:data:`linkopt._design.maps.MAX_JUMP`).
MAX_ANGLE_STEP = 0.25
MAX_LINEAR_STEP = 0.05
#: Bytes of page data the grids of one page may hold (plotly.js adds 4.8 MB): under
#: 10 MB in all.
MAX_DATA_BYTES = 4_000_000
#: Characters a number takes in the page (nine significant digits, sign, exponent,
#: separator).
NUMBER_BYTES = 14
#: The finest default grid: cells per motor axis, and cells in all (about 10 s of
#: solving for the five-bar on one loaded core; ``--resolution`` gives more).
MAX_DEFAULT_RESOLUTION = 101
MAX_DEFAULT_CELLS = 2000


@dataclass(frozen=True)
class ViewGrid:
    """FK over a motor grid ``axes[0] × axes[1] × ...`` of one design (file units,
    rad); cells in C order (the last motor fastest)."""

    axes: tuple[np.ndarray, ...]  # (N_m,) per motor
    states: Float[np.ndarray, "C S"]  # homogenised; NaN where failed
    feasible: Bool[np.ndarray, " C"]
    f_sing: Float[np.ndarray, " C"]  # NaN where failed
    clearance: Float[np.ndarray, " C"] | None  # file units; None: no [collision]
    rest_cell: int  # the cell the continuation started from


def motor_window(mech: Mechanism, resolution: int) -> tuple[np.ndarray, np.ndarray]:
    """Low and high motor values of a grid of ``resolution`` cells per motor (module
    docstring)."""
    angle = math.pi if mech.num_motors == 1 else ANGLE_SPAN
    steps = 0.5 * (resolution - 1)
    angle = min(angle, steps * MAX_ANGLE_STEP)
    linear = min(LINEAR_SPAN, steps * MAX_LINEAR_STEP) * mech.length_scale
    span = np.where(mech.motor_linear, linear, angle)
    low, high = -span, span
    if mech.motor_limited:
        low = np.where(np.isfinite(mech.motor_min), mech.motor_min, low)
        high = np.where(np.isfinite(mech.motor_max), mech.motor_max, high)
    return np.asarray(low, float), np.asarray(high, float)


def cell_bytes(mech: Mechanism) -> int:
    """Page bytes of one cell: the state of its parts (a welded body's parts drawn
    apart), ``f_sing`` and the clearance."""
    return NUMBER_BYTES * (7 * parts(mech).num_bodies + 2)


def default_resolution(mech: Mechanism, designs: int = 1) -> int:
    """The finest grid (cells per motor axis, odd so that rest is a cell where the
    window is symmetric) whose ``designs`` grids fit :data:`MAX_DATA_BYTES` and
    :data:`MAX_DEFAULT_CELLS` cells together; at least 2, at most
    :data:`MAX_DEFAULT_RESOLUTION` per axis."""
    cells = min(MAX_DATA_BYTES / cell_bytes(mech), MAX_DEFAULT_CELLS) / designs
    n = int(math.floor(cells ** (1 / mech.num_motors) + 1e-9))
    n = min(n, MAX_DEFAULT_RESOLUTION)
    return max(2, n if n % 2 or n <= 2 else n - 1)


def largest_resolution(mech: Mechanism, designs: int = 1) -> int:
    """The most cells per motor axis whose ``designs`` grids fit
    :data:`MAX_DATA_BYTES` (1: not even 2)."""
    cells = MAX_DATA_BYTES / (designs * cell_bytes(mech))
    n = int(math.floor(cells ** (1 / mech.num_motors) + 1e-9))
    return n + 1 if (n + 1) ** mech.num_motors <= cells else n


def check_view_grid(mech: Mechanism, resolution, designs: int = 1) -> int:
    """``resolution`` (None: :func:`default_resolution`) as cells per motor axis, or
    :class:`InputError` saying what it costs when the page would hold more than
    :data:`MAX_DATA_BYTES` (a mechanism with too many motors for even a 2-cell axis
    is told so)."""
    m = mech.num_motors
    if resolution is None:
        resolution = default_resolution(mech, designs)
    resolution = check_count(resolution, "--resolution", 2)
    size = designs * resolution**m * cell_bytes(mech)
    if size <= MAX_DATA_BYTES:
        return resolution
    cost = grid_cost(mech, (resolution,) * m, resolution**m, designs)
    what = (
        f"--resolution {resolution}: {m} motors make {resolution}^{m} = "
        f"{resolution**m:.4g} configurations per design"
    )
    largest = largest_resolution(mech, designs)
    fits = designs * 2**m * cell_bytes(mech) <= MAX_DATA_BYTES
    advice = (
        f"give --resolution {largest} or less"
        if fits
        else (f"{m} motors are too many for a page even at --resolution 2")
    )
    raise InputError(
        f"{what}: a page of about {size / 1e6:.3g} MB of data (the limit is "
        f"{MAX_DATA_BYTES / 1e6:.3g} MB) and {_hours(cost.seconds)} of solving on "
        f"one core; {advice}"
    )


def _hours(seconds: float) -> str:
    return f"{seconds / 3600:.3g} h" if seconds >= 3600 else f"{seconds:.3g} s"


def view_grid(
    mech: Mechanism,
    resolution: int,
    design=None,
    progress: Callable[[int, int], None] | None = None,
) -> ViewGrid:
    """FK of ``design`` (None: the file's) over the motor grid (module docstring),
    by continuation from the rest pose; ``progress(visited, cells)`` per wave."""
    low, high = motor_window(mech, resolution)
    axes = tuple(np.linspace(lo, hi, resolution) for lo, hi in zip(low, high))
    zero = np.zeros(mech.num_motors)
    states, feasible = solve_grid(
        mech, "fk", axes, zero, rest_state(mech), design, progress
    )
    rest_cell = tuple(int(np.argmin(np.abs(ax))) for ax in axes)
    flat = states.reshape(-1, mech.state_size)
    ok = feasible.ravel()
    fs = np.full(len(flat), np.nan)
    if ok.any():
        fs[ok] = np.asarray(f_sing(mech, flat[ok], design=design))
    least = least_clearance(mech, flat, ok, design)
    return ViewGrid(
        axes=axes,
        states=np.where(ok[:, None], flat, np.nan),
        feasible=ok,
        f_sing=fs,
        clearance=least,
        rest_cell=int(np.ravel_multi_index(rest_cell, feasible.shape)),
    )
