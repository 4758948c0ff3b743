"""Space plots (matplotlib Agg): the motor- and end-effector-space maps of a design, as
the paper's Fig. 2, 4 and 6.

Depends on the core, never the reverse. Colours follow the paper: brighter = closer to
a singularity (``f_sing``, log scale, colour bar), black = infeasible or off the rest
branch, magenta contour = the target range in end-effector space and its preimage in
motor space, white circles = IK samples, magenta crosses = adversarial samples, orange
dashed lines = the motor limits (a file that has them). The
maps themselves are :mod:`linkopt._draw.plot_maps`'.
"""

from __future__ import annotations

import itertools
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import matplotlib
import numpy as np
from jaxtyping import Bool, Float
from matplotlib.colors import LogNorm, Normalize

from .._design.evaluation import Evaluation
from .._design.maps import MAX_BYTES, MAX_CELLS, Map2D, check_plot_resolution
from .._engine.arguments import check_design
from .._engine.collision import has_collision
from .._engine.model import Mechanism
from .._engine.readout import output_values
from . import figures, labels
from .plot_maps import check_spaces, section_maps, space_maps

MAGENTA = "#ff00ff"
#: Colours of the clearance maps: red closer than the clearance, white at it, blue
#: clear (:func:`clearance_layer`).
CLEARANCE_CMAP = "RdBu"


@dataclass(frozen=True)
class _Layer:
    """What a row of panels shows: a :class:`~linkopt._design.maps.Map2D` field, its
    colours and scale, its colour bar's label and its panels' title prefix."""

    field: str  # "f_sing" or "clearance"
    cmap: str
    norm: object
    label: str
    prefix: str = ""


F_SING_LABEL = "f_sing (brighter = closer to a singularity)"


def clearance_layer(mech: Mechanism, grids: list[Map2D]) -> _Layer | None:
    """The clearance maps' layer: :data:`CLEARANCE_CMAP` on a scale symmetric about the
    file's ``[collision].clearance`` ``c`` (white at ``c``; its half-width the largest
    distance of a cell's clearance from ``c``); None when no grid has a finite
    clearance (the file checks no collisions, or no pair, or nothing is reached)."""
    values = [
        g.clearance[np.isfinite(g.clearance)] for g in grids if g.clearance is not None
    ]
    values = np.concatenate(values) if values else np.zeros(0)
    if not values.size:
        return None
    band = mech.collision.clearance
    half = max(float(np.max(np.abs(values - band))), 1e-9 * band)
    unit = mech.raw.get("mechanism", {}).get("units", "")
    unit = f" ({unit})" if isinstance(unit, str) and unit else ""
    label = f"least clearance between links{unit}; red: closer than {band:.3g}"
    norm = Normalize(vmin=band - half, vmax=band + half)
    return _Layer("clearance", CLEARANCE_CMAP, norm, label, "least clearance: ")


def band_contours(ax, grid: Map2D, band: float) -> None:
    """Contour lines of a clearance map at the clearance ``band`` (dashed) and at
    contact, clearance 0 (solid), where the map crosses them."""
    values = grid.clearance
    finite = values[np.isfinite(values)]
    levels = [v for v in (0.0, band) if finite.size and finite.min() < v < finite.max()]
    if levels:
        ax.contour(
            grid.axis0,
            grid.axis1,
            values.T,
            levels=levels,
            colors="k",
            linewidths=1.2,
            linestyles=["-" if v == 0.0 else "--" for v in levels],
        )


def _panel(ax, grid: Map2D, layer: _Layer, title: str, labels):
    extent = [grid.axis0[0], grid.axis0[-1], grid.axis1[0], grid.axis1[-1]]
    ax.set_facecolor("black")
    cmap = matplotlib.colormaps[layer.cmap].with_extremes(bad="black")
    image = ax.imshow(
        getattr(grid, layer.field).T,
        origin="lower",
        extent=extent,
        aspect="auto",
        cmap=cmap,
        norm=layer.norm,
        interpolation="nearest",
    )
    ax.set_title(layer.prefix + title)
    ax.set_xlabel(labels[0])
    ax.set_ylabel(labels[1])
    return image


def _inside(mech: Mechanism, outputs: np.ndarray) -> np.ndarray:
    inside = np.all(
        (outputs >= mech.output_min) & (outputs <= mech.output_max), axis=-1
    )
    return np.where(np.isnan(outputs[..., 0]), 0.0, inside.astype(float))


def _nearest(values: np.ndarray, cuts) -> np.ndarray:
    """Index of the cut nearest to each value."""
    return np.argmin(np.abs(values[:, None] - np.asarray(cuts)[None, :]), axis=1)


@dataclass(frozen=True)
class _Row:
    """One row of :func:`plot_spaces`: a motor- and an end-effector-space map, their
    title suffixes, and which IK and adversarial samples the row shows."""

    motors: Map2D
    outputs: Map2D
    at_motor: str
    at_output: str
    ik: Bool[np.ndarray, " T"]
    adv: Bool[np.ndarray, " T"]


@dataclass(frozen=True)
class _Samples:
    """The samples in motor space (``a``) and end-effector space (``b``), file
    units."""

    ik_a: Float[np.ndarray, "T M"]
    adv_a: Float[np.ndarray, "T M"]
    ik_b: Float[np.ndarray, "T K"]
    adv_b: Float[np.ndarray, "T K"]


def _samples(mech: Mechanism, evaluation: Evaluation, design) -> _Samples:
    return _Samples(
        np.asarray(evaluation.ik_motors) * mech.motor_scale,
        np.asarray(evaluation.adv_motors) * mech.motor_scale,
        np.asarray(output_values(mech, evaluation.ik_states, design=design)),
        np.asarray(output_values(mech, evaluation.adv_states, design=design)),
    )


def _section_rows(
    mech: Mechanism,
    evaluation: Evaluation,
    resolution: int,
    design,
    samples: _Samples,
    progress=None,
) -> list[_Row]:
    """Three motors and outputs: one row per section, with the samples whose third
    output is nearest to it."""
    cuts = section_maps(mech, evaluation, resolution, design, progress)
    b_cuts = [c[3] for c in cuts]
    return [
        _Row(
            motors,
            outputs,
            f" at {mech.motor_names[2]} = {a_cut:.3g} {labels.motor_unit(mech, 2)}",
            f" at {mech.output_names[2]} = {b_cut:.3g} {labels.output_unit(mech, 2)}",
            _nearest(samples.ik_b[:, 2], b_cuts) == k,
            _nearest(samples.adv_b[:, 2], b_cuts) == k,
        )
        for k, (motors, outputs, a_cut, b_cut) in enumerate(cuts)
    ]


def _rows(
    mech: Mechanism,
    evaluation: Evaluation,
    resolution: int,
    design,
    samples: _Samples,
    progress=None,
) -> list[_Row]:
    """The figure's rows: one for two motors and outputs, one per section for
    three."""
    if mech.num_motors == 2 and mech.num_outputs == 2:
        motors, outputs = space_maps(mech, evaluation, resolution, design, progress)
        every_ik = np.ones(len(samples.ik_a), bool)
        return [
            _Row(motors, outputs, "", "", every_ik, np.ones(len(samples.adv_a), bool))
        ]
    check_spaces(mech, (3,), "space plots")
    return _section_rows(mech, evaluation, resolution, design, samples, progress)


def _colour_norm(rows: list[_Row]) -> LogNorm:
    """One log colour scale over the feasible cells of every map."""
    values = np.concatenate(
        [
            np.concatenate(
                [
                    r.motors.f_sing[r.motors.feasible],
                    r.outputs.f_sing[r.outputs.feasible],
                ]
            )
            for r in rows
        ]
    )
    return LogNorm(
        vmin=max(np.min(values), 1e-3),
        vmax=max(np.percentile(values, 99), np.min(values) * 10),
    )


def _scatter_samples(ax, ik: Float[np.ndarray, "n 2"], adv: Float[np.ndarray, "m 2"]):
    """IK samples as white circles, adversarial samples as magenta crosses."""
    ax.scatter(
        ik[:, 0],
        ik[:, 1],
        s=40,
        facecolors="none",
        edgecolors="white",
        linewidths=1.5,
        label="IK samples",
        zorder=3,
    )
    ax.scatter(
        adv[:, 0],
        adv[:, 1],
        s=40,
        marker="x",
        color=MAGENTA,
        linewidths=1.8,
        label="adversarial samples",
        zorder=4,
    )


#: Colour of the motor limits in motor space (:func:`limit_lines`).
LIMIT_COLOUR = "#ffa500"


def limit_lines(ax, mech: Mechanism) -> int:
    """The first two motors' limits as dashed lines in motor space (vertical for the
    first motor, horizontal for the second; none for a side without a limit or a
    file without limits); returns how many it drew."""
    if not mech.motor_limited:
        return 0
    drawn = 0
    for motor, line in ((0, ax.axvline), (1, ax.axhline)):
        for value in (mech.motor_min[motor], mech.motor_max[motor]):
            if np.isfinite(value):
                label = "motor limits" if not drawn else None
                line(value, color=LIMIT_COLOUR, ls="--", lw=1.8, label=label, zorder=5)
                drawn += 1
    return drawn


def _draw_row(mech: Mechanism, left, right, row: _Row, layer: _Layer, samples):
    """Both panels of a row, the target range in each, and the samples; returns the
    right panel's image (for the colour bar)."""
    motor_labels, output_labels = labels.motor_labels(mech), labels.output_labels(mech)
    lo, hi = mech.output_min, mech.output_max
    _panel(left, row.motors, layer, "motor space" + row.at_motor, motor_labels)
    image = _panel(
        right, row.outputs, layer, "end-effector space" + row.at_output, output_labels
    )
    inside = _inside(mech, row.motors.outputs)
    if 0.0 < inside.max():
        left.contour(
            row.motors.axis0,
            row.motors.axis1,
            inside.T,
            levels=[0.5],
            colors=MAGENTA,
            linewidths=2,
        )
    right.plot(
        [lo[0], hi[0], hi[0], lo[0], lo[0]],
        [lo[1], lo[1], hi[1], hi[1], lo[1]],
        color=MAGENTA,
        lw=2,
    )
    for ax, grid in ((left, row.motors), (right, row.outputs)):
        if layer.field == "clearance":
            band_contours(ax, grid, mech.collision.clearance)
        else:
            _reported_contours(ax, mech, grid)
    _scatter_samples(left, samples.ik_a[row.ik], samples.adv_a[row.adv])
    limit_lines(left, mech)
    _scatter_samples(right, samples.ik_b[row.ik], samples.adv_b[row.adv])
    right.legend(loc="upper right", fontsize=8, facecolor="0.85")
    return image


#: Contour lines of a reported output over a map.
REPORTED_LEVELS = 7


def _reported_contours(ax, mech: Mechanism, grid: Map2D) -> None:
    """Dashed, labelled contour lines of the file's first reported output
    (``reported = true``) over the reached cells of a map, named in a corner.

    They cost a read-out of the map's solved states (:func:`~.maps._finish`), no solve.
    Only the first: a second set of contours over the same map is not legible (our
    choice; ``linkopt.reported_values`` reads them all). Nothing is drawn when the
    file has none or the output is constant over the map."""
    if grid.reported is None:
        return
    values = grid.reported[..., 0]
    finite = values[np.isfinite(values)]
    if finite.size < 4 or np.ptp(finite) <= 1e-12 * max(1.0, np.abs(finite).max()):
        return
    lines = ax.contour(
        grid.axis0,
        grid.axis1,
        values.T,
        levels=REPORTED_LEVELS,
        colors="0.9",
        linewidths=0.8,
        linestyles="--",
    )
    ax.clabel(lines, fontsize=7, fmt="%.3g")
    ax.text(
        0.02,
        0.02,
        f"dashed: reported {mech.reported_table.names[0]}",
        transform=ax.transAxes,
        fontsize=8,
        color="0.9",
    )


def _spaces_title(mech: Mechanism, evaluation: Evaluation) -> str:
    share = evaluation.f_design - evaluation.reach - evaluation.singularity
    collision = f", collision {float(share):.3g}" if has_collision(mech) else ""
    return (
        f"{mech.name}: f_design = {float(evaluation.f_design):.3g} "
        f"(reach {float(evaluation.reach):.3g}, "
        f"singularity {float(evaluation.singularity):.3g}{collision})"
    )


def plot_spaces(
    mech: Mechanism,
    evaluation: Evaluation,
    path: str | Path,
    *,
    resolution: int | None = None,
    design=None,
    title: str = "",
    max_cells: int = MAX_CELLS,
    max_bytes: int = MAX_BYTES,
    progress: Callable[[dict], None] | None = None,
    clearance: bool = True,
) -> Path:
    """Motor space (left) and end-effector space (right), as the paper's Fig. 2/4/6; for
    three motors and outputs, one row per 2-D section (:func:`section_maps`), each
    showing the samples whose third coordinate is nearest to that section.

    With ``clearance`` and ``[collision]`` enabled, each row of ``f_sing`` maps has a
    row of the same maps below it coloured by each cell's least clearance between the
    checked links (:func:`clearance_layer`).

    The mechanism, ``resolution`` (a whole number ≥ 2, within the limits of
    :func:`linkopt._design.maps.check_plot_resolution`; default by the number of
    outputs, :data:`linkopt._design.maps.PLOT_RESOLUTION`) and ``design`` are checked
    before any work. ``progress`` gets ``{"stage", "cells", "of"}`` after each wave of
    every map's continuation."""
    check_spaces(mech, (2, 3), "space plots")
    resolution = check_plot_resolution(
        mech, resolution, max_cells=max_cells, max_bytes=max_bytes
    )
    check_design(mech, design)
    samples = _samples(mech, evaluation, design)
    rows = _rows(mech, evaluation, resolution, design, samples, progress)
    layers = [_Layer("f_sing", "viridis", _colour_norm(rows), F_SING_LABEL)]
    extra = clearance_layer(mech, [m for r in rows for m in (r.motors, r.outputs)])
    layers += [extra] if clearance and extra is not None else []
    count = len(layers)
    fig, axes = figures.subplots(
        len(rows) * count,
        2,
        figsize=(12, 5.2 * len(rows) * count),
        constrained_layout=True,
        squeeze=False,
    )
    for k, (row, layer) in enumerate(itertools.product(rows, layers)):
        image = _draw_row(mech, *axes[k], row, layer, samples)
        if k < count:
            fig.colorbar(image, ax=axes[k::count].ravel().tolist(), label=layer.label)
    fig.suptitle(title or _spaces_title(mech, evaluation))
    path = Path(path)
    fig.savefig(path, dpi=100)
    return path
