"""Headless figures (matplotlib Agg) of a mechanism and a run: the mechanism at rest
(several designs overlaid) and the optimisation's convergence. The space maps are
:mod:`linkopt._draw.space_plots`'.

Depends on the core, never the reverse.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np
from matplotlib.patches import Polygon

from .._engine.collision import capsule_ends, has_collision
from .._engine.geometry import design_vector, geometry, rest_state
from .._engine.model import Mechanism
from .._engine.point_moves import point_moves
from .._engine.readout import joint_positions, point_positions
from .._engine.welding import parts
from . import figures, labels
from .planar import plane_normal

MAGENTA = "#ff00ff"


def mechanism_views(mech: Mechanism) -> list[tuple[int, int]]:
    """The views of :func:`plot_mechanism`: for a planar mechanism
    (:func:`linkopt._draw.planar.plane_normal`, the test the animations use) the two
    world axes with the largest spread of its joint anchors and points at rest (a top
    view), and with ``[collision]`` enabled also a side view, the first of them and the
    third axis (where layers and lifts show); else the three orthographic views xy,
    xz, yz."""
    if plane_normal(mech) is None:
        return [(0, 1), (0, 2), (1, 2)]
    rest = rest_state(mech)
    anchors = np.concatenate(
        [
            np.asarray(joint_positions(mech, rest)),
            np.asarray(point_positions(mech, rest)).reshape(-1, 3),
        ]
    )
    first, second, third = (int(k) for k in np.argsort(np.ptp(anchors, axis=0))[::-1])
    top = tuple(sorted((first, second)))
    return [top, tuple(sorted((first, third)))] if has_collision(mech) else [top]


def _stadium(p, q, radius: float, count: int = 17) -> np.ndarray:
    """Outline ``(2 count, 2)`` of a 2-D capsule: the segment ``p q`` widened by
    ``radius``, half circles at its ends (a circle for a zero-length segment)."""
    d = q - p
    angle = np.arctan2(d[1], d[0]) if np.any(d) else 0.0
    a = angle + np.linspace(-np.pi / 2, np.pi / 2, count)
    ring = radius * np.stack([np.cos(a), np.sin(a)], axis=1)
    return np.vstack([q + ring, p - ring])


def _capsules(ax, mech: Mechanism, design, colour: str, plane) -> None:
    """The link solids of a file with ``[collision]`` enabled, at rest: each capsule
    (:mod:`linkopt._engine.collision`, the solids checked and exported) projected on
    the view, translucent, at its true radius."""
    geom = geometry(mech, design_vector(mech, design))
    ends = np.asarray(capsule_ends(mech, geom, rest_state(mech))) * mech.length_scale
    for (p, q), radius in zip(ends[:, :, list(plane)], mech.collision.segment_radii):
        outline = _stadium(p, q, float(radius))
        ax.add_patch(Polygon(outline, facecolor=colour, edgecolor=colour, alpha=0.3))


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


def mark_moves(ax, mech: Mechanism, design, colour: str, plane) -> int:
    """Mark each named point that ``design`` moves by more than
    :data:`~linkopt._engine.point_moves.MOVE_SHARE` of its body's anchor span: a
    hollow circle at its rest position at the initial design, a dashed line to where
    the design puts it (lines have the gid ``moved-point``). Returns how many."""
    if design is None:
        return 0
    moves = point_moves(mech, np.asarray(design, dtype=float)[None])
    u, v = plane
    for move in moves:
        ax.plot(
            [move.rest[u], move.moved[u]],
            [move.rest[v], move.moved[v]],
            "--",
            color=colour,
            lw=1.2,
            gid="moved-point",
            label=f"{move.point} moved {100 * move.share:.3g} % of {move.body}",
        )
        ax.scatter(
            [move.rest[u]], [move.rest[v]], s=90, facecolors="none", edgecolors=colour
        )
    return len(moves)


def _views(planes: list) -> tuple:
    """The figure and its axes (flat) for the views: side by side, or a planar
    mechanism's top view above its side view (:func:`mechanism_views`), which is
    short."""
    if len(planes) == 2:
        fig, axes = figures.subplots(
            2, 1, figsize=(7.5, 9.0), height_ratios=[3, 1], constrained_layout=True
        )
        return fig, list(axes)
    fig, axes = figures.subplots(
        1,
        len(planes),
        figsize=(6.5 * len(planes), 6.5),
        constrained_layout=True,
        squeeze=False,
    )
    return fig, list(axes[0])


def plot_mechanism(
    mech: Mechanism,
    path: str | Path,
    *,
    designs: dict[str, np.ndarray | None] | None = None,
) -> Path:
    """The mechanism at rest (joint circles, motor squares, ground triangles, point
    stars); several designs are overlaid, the first in grey. A planar mechanism is
    drawn in its plane, a spatial one in three orthographic views
    (:func:`mechanism_views`). A point that a design moves far on its body is marked
    (:func:`mark_moves`). With ``[collision]`` enabled the link solids are drawn
    too, and a planar mechanism gets a side view as well, where their layers
    show. Welded parts are drawn as the file's bodies
    (:func:`~linkopt._engine.welding.parts`)."""
    mech = parts(mech)
    designs = designs or {"initial": None}
    planes = mechanism_views(mech)
    fig, axes = _views(planes)
    colours = ["0.55", "tab:blue", "tab:orange", "tab:green"]
    for ax, plane in zip(axes, planes):
        for (label, design), colour in zip(designs.items(), colours):
            _draw(ax, mech, design, colour, label, 1.0, plane)
            mark_moves(ax, mech, design, colour, plane)
            if has_collision(mech):
                _capsules(ax, mech, design, colour, plane)
        _target_box(ax, mech, plane)
        ax.set_aspect("equal")
        unit = f" ({labels.length_unit(mech) or 'length units'})"
        ax.set_xlabel("xyz"[plane[0]] + unit)
        ax.set_ylabel("xyz"[plane[1]] + unit)
        view = "" if len(planes) == 1 else f" ({'xyz'[plane[0]]}{'xyz'[plane[1]]} view)"
        ax.set_title(f"{mech.name} at rest{view}")
    axes[0].legend(loc="best", fontsize=8)
    path = Path(path)
    fig.savefig(path, dpi=100)
    return path


def plot_convergence(
    history: Sequence[dict], path: str | Path, *, title: str = ""
) -> Path:
    """The returned design's total (``best_total``) and its parts per iteration, and
    each iteration's best total as dots (log scale). The returned design is the best
    seen, feasible first and then by total
    (:func:`linkopt._design.optimizer.record_iteration`): its total never rises within
    a verification round except where the first feasible design replaces a lower
    infeasible one, marked by a dotted line; a dashed line marks each round's start
    (the added targets change every cost)."""
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
            label=key.replace("_", " ")
            + (" (returned)" if key == "best_total" else ""),
        )
    ax.semilogy(
        it,
        [max(h.get("iteration_total", h["best_total"]), floor) for h in history],
        "k.",
        alpha=0.5,
        label="iteration's best total",
    )
    _mark_changes(ax, history)
    ax.set_xlabel("iteration")
    ax.set_ylabel("value (returned design)")
    ax.set_title(title)
    ax.legend(fontsize=8)
    path = Path(path)
    fig.savefig(path, dpi=100)
    return path


def _mark_changes(ax, history: Sequence[dict]) -> None:
    """Vertical lines where a verification round starts (dashed) and where the
    returned design first becomes feasible in a round (dotted)."""
    for before, h in zip(history, history[1:]):
        if h.get("round", 0) != before.get("round", 0):
            ax.axvline(h["iteration"] - 0.5, color="0.6", linestyle="--", lw=0.8)
        elif h.get("feasible") and not before.get("feasible"):
            ax.axvline(h["iteration"] - 0.5, color="0.6", linestyle=":", lw=0.8)
