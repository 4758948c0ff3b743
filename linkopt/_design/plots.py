"""Headless figures (matplotlib Agg): motor/end-effector space maps and mechanism
drawings.

Depends on the core, never the reverse. Colours follow the paper's Fig. 2, 4 and 6:
brighter = closer to a singularity (``f_sing``, log scale, colour bar), black =
infeasible or off the rest branch, magenta contour = the target range in end-effector
space and its preimage in motor space, white circles = IK samples, magenta crosses =
adversarial samples.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path
from typing import NamedTuple

import matplotlib
import numpy as np
from jaxtyping import Bool, Float
from matplotlib.colors import LogNorm

from .. import _figures as figures
from .._engine.geometry import rest_state
from .._engine.kinematics import check_design
from .._engine.model import Mechanism
from .._engine.readout import (
    joint_positions,
    output_values,
    point_positions,
)
from .._errors import InputError
from .evaluation import Evaluation
from .maps import (
    MAX_BYTES,
    MAX_CELLS,
    Map2D,
    check_plot_resolution,
    motor_map,
    output_map,
    sections,
)

MAGENTA = "#ff00ff"
PADDING = 0.35


def _window(points: np.ndarray, low, high, pad: float):
    low = np.minimum(np.min(points, axis=0), low)
    high = np.maximum(np.max(points, axis=0), high)
    span = np.maximum(high - low, 1e-9)
    return low - pad * span, high + pad * span


def plot_windows(mech: Mechanism, evaluation: Evaluation, rest, design):
    """The maps' motor window (the samples and the rest pose, at least ±0.3, padded)
    and output window (the target range and the rest outputs, padded 20 %), and the
    rest outputs."""
    samples = np.concatenate(
        [np.asarray(evaluation.ik_motors), np.asarray(evaluation.adv_motors)]
    )
    motors = _window(
        np.vstack([samples * mech.motor_scale, np.zeros((1, mech.num_motors))]),
        -0.3,
        0.3,
        PADDING,
    )
    rest_out = np.asarray(output_values(mech, rest, design=design))
    outputs = _window(
        np.vstack([rest_out, mech.output_min, mech.output_max]),
        mech.output_min,
        mech.output_max,
        0.2,
    )
    return motors, outputs, rest_out


def space_maps(
    mech: Mechanism, evaluation: Evaluation, resolution: int, design=None, progress=None
) -> tuple[Map2D, Map2D]:
    """Continuation maps around the target range and the samples (two motors, two
    outputs)."""
    _check_spaces(mech, (2,), "space maps")
    rest = rest_state(mech)
    (m_low, m_high), (o_low, o_high), rest_out = plot_windows(
        mech, evaluation, rest, design
    )
    motors = motor_map(
        mech,
        m_low,
        m_high,
        resolution,
        start_state=rest,
        start_motors=np.zeros(2),
        design=design,
        progress=progress,
    )
    outputs = output_map(
        mech,
        o_low,
        o_high,
        resolution,
        start_state=rest,
        start_outputs=rest_out,
        design=design,
        progress=progress,
    )
    return motors, outputs


def _panel(ax, grid: Map2D, norm, title: str, labels):
    extent = [grid.axis0[0], grid.axis0[-1], grid.axis1[0], grid.axis1[-1]]
    ax.set_facecolor("black")
    cmap = matplotlib.colormaps["viridis"].with_extremes(bad="black")
    image = ax.imshow(
        grid.f_sing.T,
        origin="lower",
        extent=extent,
        aspect="auto",
        cmap=cmap,
        norm=norm,
        interpolation="nearest",
    )
    ax.set_title(title)
    ax.set_xlabel(labels[0])
    ax.set_ylabel(labels[1])
    return image


def _inside(mech: Mechanism, outputs: np.ndarray) -> np.ndarray:
    inside = np.all(
        (outputs >= mech.output_min) & (outputs <= mech.output_max), axis=-1
    )
    return np.where(np.isnan(outputs[..., 0]), 0.0, inside.astype(float))


#: Where the motor-space sections cut the third motor's range over the IK samples
#: (:func:`section_maps`).
SECTION_FRACTIONS = (0.25, 0.5, 0.75)


def section_maps(
    mech: Mechanism, evaluation: Evaluation, resolution: int, design=None, progress=None
):
    """Three motors and three outputs: 2-D sections of both spaces at three values of
    the third variable (output: the range's ends and middle; motor: a quarter, half and
    three quarters of the way between the smallest and largest third motor value of
    the IK samples, so that each motor section cuts the target range's image, whose
    third motor values span that interval, where its ends would only touch it).
    Returns
    ``[(motor_map, output_map, motor_cut, output_cut)]``, one per section."""
    _check_spaces(mech, (3,), "sections")
    rest = rest_state(mech)
    ik_motors = np.asarray(evaluation.ik_motors) * mech.motor_scale
    (m_low, m_high), (o_low, o_high), rest_out = plot_windows(
        mech, evaluation, rest, design
    )
    b_cuts = [
        mech.output_min[2],
        0.5 * (mech.output_min[2] + mech.output_max[2]),
        mech.output_max[2],
    ]
    third = ik_motors[:, 2]
    a_cuts = [float(np.min(third) + f * np.ptp(third)) for f in SECTION_FRACTIONS]
    motors = sections(
        mech,
        "fk",
        m_low,
        m_high,
        resolution,
        a_cuts,
        start_state=rest,
        start_values=np.zeros(3),
        design=design,
        progress=progress,
    )
    outputs = sections(
        mech,
        "bk",
        o_low,
        o_high,
        resolution,
        b_cuts,
        start_state=rest,
        start_values=rest_out,
        design=design,
        progress=progress,
    )
    return list(zip(motors, outputs, a_cuts, b_cuts))


def _nearest(values: np.ndarray, cuts) -> np.ndarray:
    """Index of the cut nearest to each value."""
    return np.argmin(np.abs(values[:, None] - np.asarray(cuts)[None, :]), axis=1)


class _Row(NamedTuple):
    """One row of :func:`plot_spaces`: a motor- and an end-effector-space map, their
    title suffixes, and which IK and adversarial samples the row shows."""

    motors: Map2D
    outputs: Map2D
    at_motor: str
    at_output: str
    ik: Bool[np.ndarray, " T"]
    adv: Bool[np.ndarray, " T"]


class _Samples(NamedTuple):
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
            f" at {mech.motor_names[2]} = {a_cut:.3g}",
            f" at {mech.output_names[2]} = {b_cut:.3g}",
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
    _check_spaces(mech, (3,), "space plots")
    return _section_rows(mech, evaluation, resolution, design, samples, progress)


def _check_spaces(mech: Mechanism, counts: tuple[int, ...], what: str) -> None:
    """:class:`InputError` unless the mechanism has ``counts`` motors and as many
    outputs."""
    if mech.num_motors != mech.num_outputs or mech.num_motors not in counts:
        expected = " or ".join(map(str, counts))
        raise InputError(
            f"{mech.source}: {what} need {expected} motors and as many outputs, the "
            f"file has {mech.num_motors} and {mech.num_outputs}"
        )


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


def _draw_row(mech: Mechanism, left, right, row: _Row, norm, samples: _Samples):
    """Both panels of a row, the target range in each, and the samples; returns the
    right panel's image (for the colour bar)."""
    motor_labels = [
        f"motor {n} ({'rad' if not lin else 'length'})"
        for n, lin in zip(mech.motor_names, mech.motor_linear)
    ]
    output_labels = [f"output {n}" for n in mech.output_names]
    lo, hi = mech.output_min, mech.output_max
    _panel(left, row.motors, norm, "motor space" + row.at_motor, motor_labels)
    image = _panel(
        right, row.outputs, norm, "end-effector space" + row.at_output, output_labels
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
        _reported_contours(ax, mech, grid)
    _scatter_samples(left, samples.ik_a[row.ik], samples.adv_a[row.adv])
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
    return (
        f"{mech.name}: f_design = {float(evaluation.f_design):.3g} "
        f"(reach {float(evaluation.reach):.3g}, "
        f"singularity {float(evaluation.singularity):.3g})"
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
) -> Path:
    """Motor space (left) and end-effector space (right), as the paper's Fig. 2/4/6; for
    three motors and outputs, one row per 2-D section (:func:`section_maps`), each
    showing the samples whose third coordinate is nearest to that section.

    The mechanism, ``resolution`` (a whole number ≥ 2, within the limits of
    :func:`linkopt._design.maps.check_plot_resolution`; default by the number of
    outputs, :data:`linkopt._design.maps.PLOT_RESOLUTION`) and ``design`` are checked
    before any work. ``progress`` gets ``{"stage", "cells", "of"}`` after each wave of
    every map's continuation."""
    _check_spaces(mech, (2, 3), "space plots")
    resolution = check_plot_resolution(
        mech, resolution, max_cells=max_cells, max_bytes=max_bytes
    )
    check_design(mech, design)
    samples = _samples(mech, evaluation, design)
    rows = _rows(mech, evaluation, resolution, design, samples, progress)
    norm = _colour_norm(rows)
    fig, axes = figures.subplots(
        len(rows),
        2,
        figsize=(12, 5.2 * len(rows)),
        constrained_layout=True,
        squeeze=False,
    )
    for (left, right), row in zip(axes, rows):
        image = _draw_row(mech, left, right, row, norm, samples)
    fig.colorbar(
        image,
        ax=axes.ravel().tolist(),
        label="f_sing (brighter = closer to a singularity)",
    )
    fig.suptitle(title or _spaces_title(mech, evaluation))
    path = Path(path)
    fig.savefig(path, dpi=100)
    return path


#: Relative spread (smallest over largest singular value of the centred rest anchors)
#: above which a mechanism is drawn in three orthographic views, not one plane.
SPATIAL = 1e-6


def _planes(mech: Mechanism) -> list[tuple[int, int]]:
    """The views of :func:`plot_mechanism`: for joint anchors and points in one plane
    at rest (up to :data:`SPATIAL`) the two world axes with the largest spread of them
    (a top view of a planar mechanism), else the three orthographic views xy, xz,
    yz."""
    rest = rest_state(mech)
    anchors = np.concatenate(
        [
            np.asarray(joint_positions(mech, rest)),
            np.asarray(point_positions(mech, rest)).reshape(-1, 3),
        ]
    )
    spread = np.linalg.svd(anchors - anchors.mean(axis=0), compute_uv=False)
    if spread[0] > 0 and spread[-1] > SPATIAL * spread[0]:
        return [(0, 1), (0, 2), (1, 2)]
    first, second = np.argsort(np.ptp(anchors, axis=0))[::-1][:2]
    return [tuple(sorted((int(first), int(second))))]


def _target_box(ax, mech: Mechanism, plane: tuple[int, int]) -> None:
    """The target range's rectangle, where two outputs are the view's two Cartesian
    coordinates of one point."""
    coords = {}
    for k, (kind, c) in enumerate(zip(mech.output_kinds, mech.output_coords)):
        if kind == "position" and int(c) in plane:
            coords.setdefault(int(c), []).append(k)
    if sorted(coords) != list(plane) or any(len(v) != 1 for v in coords.values()):
        return
    (i,), (j,) = coords[plane[0]], coords[plane[1]]
    if mech.output_points[i] != mech.output_points[j]:
        return
    lo, hi = mech.output_min, mech.output_max
    ax.plot(
        [lo[i], hi[i], hi[i], lo[i], lo[i]],
        [lo[j], lo[j], hi[j], hi[j], lo[j]],
        color=MAGENTA,
        lw=1.5,
        label="target range",
    )


def _draw(ax, mech: Mechanism, design, colour: str, label: str, alpha: float, plane):
    state = rest_state(mech)
    joints = np.asarray(joint_positions(mech, state, design=design))
    points = np.asarray(point_positions(mech, state, design=design))
    u, v = plane
    for b in range(mech.num_bodies):
        members = [
            joints[k] for k in range(len(mech.joint_names)) if b in mech.joint_bodies[k]
        ]
        members += [
            points[k] for k in range(len(mech.point_names)) if mech.point_bodies[k] == b
        ]
        coords = np.array(members)[:, [u, v]]
        if b == mech.ground:
            ax.scatter(
                coords[:, 0], coords[:, 1], marker="^", s=120, color=colour, alpha=alpha
            )
            continue
        centre = coords.mean(axis=0)
        order = np.argsort(
            np.arctan2(coords[:, 1] - centre[1], coords[:, 0] - centre[0])
        )
        ring = coords[np.append(order, order[0])]
        ax.plot(ring[:, 0], ring[:, 1], "-", color=colour, lw=3, alpha=alpha)
    ax.scatter(
        joints[:, u],
        joints[:, v],
        s=30,
        color="white",
        edgecolors=colour,
        zorder=3,
        alpha=alpha,
    )
    motor_xy = joints[mech.motor_joints][:, [u, v]]
    ax.scatter(
        motor_xy[:, 0],
        motor_xy[:, 1],
        marker="s",
        s=90,
        facecolors="none",
        edgecolors=colour,
        lw=2,
        alpha=alpha,
    )
    ax.scatter(
        points[:, u],
        points[:, v],
        marker="*",
        s=120,
        color=colour,
        alpha=alpha,
        label=label,
    )


def plot_mechanism(
    mech: Mechanism,
    path: str | Path,
    *,
    designs: dict[str, np.ndarray | None] | None = None,
) -> Path:
    """The mechanism at rest (joint circles, motor squares, ground triangles, point
    stars); several designs are overlaid, the first in grey. A planar mechanism is
    drawn in its plane, a spatial one (anchors not in one plane) in three orthographic
    views (:func:`_planes`)."""
    designs = designs or {"initial": None}
    planes = _planes(mech)
    fig, axes = figures.subplots(
        1,
        len(planes),
        figsize=(6.5 * len(planes), 6.5),
        constrained_layout=True,
        squeeze=False,
    )
    colours = ["0.55", "tab:blue", "tab:orange", "tab:green"]
    for ax, plane in zip(axes[0], planes):
        for (label, design), colour in zip(designs.items(), colours):
            _draw(ax, mech, design, colour, label, 1.0, plane)
        _target_box(ax, mech, plane)
        ax.set_aspect("equal")
        ax.set_xlabel("xyz"[plane[0]])
        ax.set_ylabel("xyz"[plane[1]])
        view = "" if len(planes) == 1 else f" ({'xyz'[plane[0]]}{'xyz'[plane[1]]} view)"
        ax.set_title(f"{mech.name} at rest{view}")
    axes[0, 0].legend(loc="best", fontsize=8)
    path = Path(path)
    fig.savefig(path, dpi=100)
    return path


def plot_convergence(
    history: Sequence[dict], path: str | Path, *, title: str = ""
) -> Path:
    """The running best total (``best_total``, non-increasing within a verification
    round) and its parts per iteration, and each iteration's best total as dots (log
    scale); histories written before the running best have only the latter."""
    it = [h["iteration"] for h in history]
    fig, ax = figures.subplots(figsize=(7, 4.5), constrained_layout=True)
    floor = 1e-16
    for key, style in (
        ("best_total", "k-"),
        ("best_f_design", "b-"),
        ("reach", "g--"),
        ("singularity", "m--"),
        ("regularizer", "0.5"),
    ):
        ax.semilogy(
            it,
            [max(h[key], floor) for h in history],
            style,
            label=key.replace("_", " ") + (" (running)" if key == "best_total" else ""),
        )
    ax.semilogy(
        it,
        [max(h.get("iteration_total", h["best_total"]), floor) for h in history],
        "k.",
        alpha=0.5,
        label="iteration's best total",
    )
    ax.set_xlabel("iteration")
    ax.set_ylabel("value (running best design)")
    ax.set_title(title)
    ax.legend(fontsize=8)
    path = Path(path)
    fig.savefig(path, dpi=100)
    return path
