"""Headless figures (matplotlib Agg): motor/end-effector space maps and mechanism
drawings.

Depends on the core, never the reverse. Colours follow the paper's Fig. 2, 4 and 6:
brighter = closer to a singularity (``f_sing``, log scale, colour bar), black =
infeasible or off the rest branch, magenta contour = the target range in end-effector
space and its preimage in motor space, white circles = IK samples, magenta crosses =
adversarial samples.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import NamedTuple

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from jaxtyping import Bool, Float  # noqa: E402
from matplotlib.colors import LogNorm  # noqa: E402

from .._engine.geometry import rest_state  # noqa: E402
from .._engine.kinematics import check_design  # noqa: E402
from .._engine.model import Mechanism  # noqa: E402
from .._engine.readout import (  # noqa: E402
    joint_positions,
    output_values,
    point_positions,
)
from .._errors import InputError  # noqa: E402
from .evaluation import Evaluation  # noqa: E402
from .maps import (  # noqa: E402
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


def _windows(mech: Mechanism, evaluation: Evaluation, rest, design):
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
    mech: Mechanism, evaluation: Evaluation, resolution: int, design=None
) -> tuple[Map2D, Map2D]:
    """Continuation maps around the target range and the samples (two motors, two
    outputs)."""
    _check_spaces(mech, (2,), "space maps")
    rest = rest_state(mech)
    (m_low, m_high), (o_low, o_high), rest_out = _windows(
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
    )
    outputs = output_map(
        mech,
        o_low,
        o_high,
        resolution,
        start_state=rest,
        start_outputs=rest_out,
        design=design,
    )
    return motors, outputs


def _panel(ax, grid: Map2D, norm, title: str, labels):
    extent = [grid.axis0[0], grid.axis0[-1], grid.axis1[0], grid.axis1[-1]]
    ax.set_facecolor("black")
    cmap = plt.get_cmap("viridis").with_extremes(bad="black")
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


def section_maps(mech: Mechanism, evaluation: Evaluation, resolution: int, design=None):
    """Three motors and three outputs: 2-D sections of both spaces at three values of
    the third variable (output: the range's ends and middle; motor: the smallest, median
    and largest third motor value of the IK samples). Returns
    ``[(motor_map, output_map, motor_cut, output_cut)]``, one per section."""
    _check_spaces(mech, (3,), "sections")
    rest = rest_state(mech)
    ik_motors = np.asarray(evaluation.ik_motors) * mech.motor_scale
    (m_low, m_high), (o_low, o_high), rest_out = _windows(
        mech, evaluation, rest, design
    )
    b_cuts = [
        mech.output_min[2],
        0.5 * (mech.output_min[2] + mech.output_max[2]),
        mech.output_max[2],
    ]
    a_cuts = list(np.quantile(ik_motors[:, 2], [0.0, 0.5, 1.0]))
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
    mech: Mechanism, evaluation: Evaluation, resolution: int, design, samples: _Samples
) -> list[_Row]:
    """Three motors and outputs: one row per section, with the samples whose third
    output is nearest to it."""
    cuts = section_maps(mech, evaluation, resolution, design)
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
    mech: Mechanism, evaluation: Evaluation, resolution: int, design, samples: _Samples
) -> list[_Row]:
    """The figure's rows: one for two motors and outputs, one per section for
    three."""
    if mech.num_motors == 2 and mech.num_outputs == 2:
        motors, outputs = space_maps(mech, evaluation, resolution, design)
        every_ik = np.ones(len(samples.ik_a), bool)
        return [
            _Row(motors, outputs, "", "", every_ik, np.ones(len(samples.adv_a), bool))
        ]
    _check_spaces(mech, (3,), "space plots")
    return _section_rows(mech, evaluation, resolution, design, samples)


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
    _scatter_samples(left, samples.ik_a[row.ik], samples.adv_a[row.adv])
    _scatter_samples(right, samples.ik_b[row.ik], samples.adv_b[row.adv])
    right.legend(loc="upper right", fontsize=8, facecolor="0.85")
    return image


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
    resolution: int = 60,
    design=None,
    title: str = "",
    max_cells: int = MAX_CELLS,
    max_bytes: int = MAX_BYTES,
) -> Path:
    """Motor space (left) and end-effector space (right), as the paper's Fig. 2/4/6; for
    three motors and outputs, one row per 2-D section (:func:`section_maps`), each
    showing the samples whose third coordinate is nearest to that section.

    The mechanism, ``resolution`` (a whole number ≥ 2, within the limits of
    :func:`linkopt._design.maps.check_plot_resolution`) and ``design`` are checked
    before any work."""
    _check_spaces(mech, (2, 3), "space plots")
    check_plot_resolution(mech, resolution, max_cells=max_cells, max_bytes=max_bytes)
    check_design(mech, design)
    samples = _samples(mech, evaluation, design)
    rows = _rows(mech, evaluation, resolution, design, samples)
    norm = _colour_norm(rows)
    fig, axes = plt.subplots(
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
    plt.close(fig)
    return path


def _plane(mech: Mechanism) -> tuple[int, int]:
    """The two world axes with the largest spread of rest anchors."""
    spread = np.ptp(mech.anchors, axis=0)
    first, second = np.argsort(spread)[::-1][:2]
    return tuple(sorted((int(first), int(second))))


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
    stars); several designs are overlaid, the first in grey."""
    designs = designs or {"initial": None}
    plane = _plane(mech)
    fig, ax = plt.subplots(figsize=(6.5, 6.5), constrained_layout=True)
    colours = ["0.55", "tab:blue", "tab:orange", "tab:green"]
    for (label, design), colour in zip(designs.items(), colours):
        _draw(ax, mech, design, colour, label, 1.0, plane)
    lo, hi = mech.output_min, mech.output_max
    kinds = set(mech.output_kinds)
    if kinds == {"position"} and mech.num_outputs == 2:
        idx = [int(c) for c in mech.output_coords]
        if sorted(idx) == list(plane):
            ax.plot(
                [lo[0], hi[0], hi[0], lo[0], lo[0]],
                [lo[1], lo[1], hi[1], hi[1], lo[1]],
                color=MAGENTA,
                lw=1.5,
                label="target range",
            )
    ax.set_aspect("equal")
    ax.set_xlabel("xyz"[plane[0]])
    ax.set_ylabel("xyz"[plane[1]])
    ax.set_title(f"{mech.name} at rest")
    ax.legend(loc="best", fontsize=8)
    path = Path(path)
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path


def plot_convergence(
    history: Sequence[dict], path: str | Path, *, title: str = ""
) -> Path:
    """Best total, f_design and its parts per iteration (log scale)."""
    it = [h["iteration"] for h in history]
    fig, ax = plt.subplots(figsize=(7, 4.5), constrained_layout=True)
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
            label=key.replace("_", " "),
        )
    ax.set_xlabel("iteration")
    ax.set_ylabel("value (best particle)")
    ax.set_title(title)
    ax.legend(fontsize=8)
    path = Path(path)
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path
