"""Figures for continuous-path synthesis (paper 002, Fig. 1, 4, 5, 6): task, obstacles,
base regions, the arm at its critical states, reachable space, swept-area bounds against
the true swept area, the discretised comparison, and a GIF of the arm tracing the task.

Plotting depends on the synthesis modules, never the reverse; every function takes an
``Axes`` or returns a ``Figure`` and leaves saving to the caller (except the GIF).
"""

from __future__ import annotations

import matplotlib
import numpy as np
from matplotlib.animation import FuncAnimation, PillowWriter
from matplotlib.patches import Circle, Rectangle, Wedge

from ..._arms.trace import geometry as geo
from ..._arms.trace.discrete import DiscreteComparison
from ..._arms.trace.swept import outline, swept_support
from ..._arms.trace.task import TraceTask
from ..._arms.trace.verify import PlanarArm, TraceVerification, critical_states
from .. import figures

PATH = dict(color="0.45", lw=2.0, zorder=3)


def draw_task(ax, task: TraceTask) -> None:
    """Path (grey, arrow at the start), obstacles (red), base rectangles (black)."""
    for p in task.primitives:
        pts = np.asarray(geo.points(p, np.linspace(0.0, 1.0, 200)))
        ax.plot(pts[:, 0], pts[:, 1], **PATH)
    first = np.asarray(geo.points(task.primitives[0], np.array([0.0, 0.05])))
    ax.annotate(
        "", first[1], first[0], arrowprops=dict(arrowstyle="->", color="0.2"), zorder=4
    )
    for x, y, r in task.obstacles:
        ax.add_patch(Circle((x, y), r, color="tab:red", alpha=0.8, zorder=2))
    for x0, y0, x1, y1 in task.base_regions:
        ax.add_patch(
            Rectangle((x0, y0), x1 - x0, y1 - y0, fill=False, ec="k", lw=1.5, zorder=2)
        )
    ax.set_aspect("equal")
    ax.set_xlabel("x")
    ax.set_ylabel("y")


def draw_arm(
    ax, state: np.ndarray, task: TraceTask, color="k", alpha=1.0, zorder=5
) -> None:
    """One state ``(n+1, 2)``: links as thick lines (width ≈ Δ in points), joints as
    dots."""
    ax.plot(
        state[:, 0],
        state[:, 1],
        "-",
        color=color,
        alpha=alpha,
        lw=3,
        solid_capstyle="round",
        zorder=zorder,
    )
    ax.plot(
        state[:-1, 0],
        state[:-1, 1],
        "o",
        color=color,
        alpha=alpha,
        ms=5,
        zorder=zorder + 1,
    )
    ax.plot(
        state[-1, 0],
        state[-1, 1],
        "s",
        color=color,
        alpha=alpha,
        ms=4,
        zorder=zorder + 1,
    )


def reachable_grid(
    task: TraceTask, design: PlanarArm, proximal_angle: float, res: int = 220
):
    """Obstacle-free reachable space of the distal pair at ``proximal_angle``: grid
    points inside the annulus (eq. 2) with all links clear of obstacles on either
    branch."""
    pts = _view_points(task, design)
    lo, hi = pts.min(0), pts.max(0)
    xs, ys = np.linspace(lo[0], hi[0], res), np.linspace(lo[1], hi[1], res)
    grid = np.stack(np.meshgrid(xs, ys), axis=-1).reshape(-1, 2)
    lengths = np.asarray(design.lengths)
    origin = np.asarray(geo.distal_origin(design.base, lengths, proximal_angle))
    ok = np.asarray(geo.reachable(origin, *design.lengths[-2:], np.asarray(grid)))
    free = np.zeros(len(grid), bool)
    for sigma in (1, -1):
        states = np.asarray(
            geo.arm_states(
                design.base, lengths, proximal_angle, np.asarray(grid), sigma
            )
        )
        clear = np.ones(len(grid), bool)
        for x, y, r in task.obstacles:
            d = np.asarray(
                geo.segment_distance(
                    np.array([x, y]),
                    np.asarray(states[:, :-1]),
                    np.asarray(states[:, 1:]),
                )
            )
            clear &= (d > r + task.link_diameter / 2).all(axis=1)
        free |= clear
    return xs, ys, (ok & free).reshape(res, res)


def _view_points(task: TraceTask, design: PlanarArm | None) -> np.ndarray:
    pts = [
        np.asarray(geo.points(p, np.linspace(0.0, 1.0, 50))) for p in task.primitives
    ]
    pts.append(task.obstacles[:, :2] + task.obstacles[:, 2:3])
    pts.append(task.obstacles[:, :2] - task.obstacles[:, 2:3])
    if len(task.base_regions):
        pts.append(task.base_regions.reshape(-1, 2))
    if design is not None:
        pts.append(
            design.base[None]
            + design.lengths.sum() * np.array([[1, 1], [-1, -1]]) * 0.9
        )
    pts = np.concatenate(pts)
    pad = 0.05 * (pts.max(0) - pts.min(0)).max()
    return np.stack([pts.min(0) - pad, pts.max(0) + pad])


def draw_reachable(ax, task: TraceTask, design: PlanarArm) -> None:
    angles = np.unique(design.proximal_angles) if design.n_links == 3 else [0.0]
    for phi in angles:
        xs, ys, mask = reachable_grid(task, design, float(phi))
        ax.contourf(
            xs,
            ys,
            mask.astype(float),
            levels=[0.5, 1.5],
            colors=["0.85"],
            alpha=0.6 if len(angles) > 1 else 1.0,
            zorder=0,
        )


def solution_figure(
    task: TraceTask, design: PlanarArm, verification: TraceVerification, title: str = ""
):
    """Task, obstacle-free reachable space (light grey), arm at the critical states of
    every primitive (one colour per primitive)."""
    fig, ax = figures.subplots(figsize=(6, 6))
    draw_reachable(ax, task, design)
    draw_task(ax, task)
    colors = matplotlib.colormaps["viridis"](np.linspace(0, 0.9, len(task.primitives)))
    for j, states in enumerate(critical_states(task, design)):
        for s in states[[0, 2, 3]]:
            draw_arm(ax, s, task, color=colors[j], alpha=0.85)
    lengths = ", ".join(f"{r:.3g}" for r in design.lengths)
    ax.set_title(title or f"{task.name}: {design.n_links} links, lengths {lengths}")
    set_limits(ax, task, design)
    return fig


def set_limits(ax, task: TraceTask, design: PlanarArm | None) -> None:
    """Axis limits that show the path, obstacles, base regions and (with a design)
    most of the arm's reach, plus a margin."""
    lo, hi = _view_points(task, design)
    ax.set_xlim(lo[0], hi[0])
    ax.set_ylim(lo[1], hi[1])


def swept_figure(
    task: TraceTask, design: PlanarArm, verification: TraceVerification, kind: str
):
    """SV^kind bounds (dashed) of each primitive against the true swept area (the dense
    link positions of the verification, thin grey)."""
    fig, ax = figures.subplots(figsize=(6, 6))
    for seg in verification.segments:
        for s in seg.states[:: max(1, len(seg.states) // 120)]:
            ax.plot(s[:, 0], s[:, 1], color="0.6", lw=0.4, alpha=0.5, zorder=1)
    draw_task(ax, task)
    lengths = np.asarray(design.lengths)
    colors = matplotlib.colormaps["tab10"](np.arange(len(task.primitives)) % 10)
    for j, prim in enumerate(task.primitives):
        phi = design.proximal_angles[j] if design.n_links == 3 else 0.0
        origin = geo.distal_origin(design.base, lengths, phi)
        for h in swept_support(
            kind, prim, origin, lengths[-2], lengths[-1], design.sigma
        ):
            poly = outline(h)
            ax.plot(
                *np.vstack([poly, poly[:1]]).T, "--", color=colors[j], lw=1.0, zorder=4
            )
    ax.set_title(f"{task.name}: SV^{kind} bounds (dashed) and swept links (grey)")
    set_limits(ax, task, design)
    return fig


def discretised_figure(task: TraceTask, cmp: DiscreteComparison):
    """Fig. 6: reachable space of the discretised design, its 25 points, and the parts
    of the continuous curve outside it (red), with a zoom on the largest excursion."""
    fig, axes = figures.subplots(1, 2, figsize=(11, 5.5))
    a, b = cmp.design.lengths
    d = np.linalg.norm(cmp.curve - cmp.design.base, axis=1)
    worst = cmp.curve[np.argmax(np.maximum(d - a - b, abs(a - b) - d))]
    for ax, zoom in zip(axes, (False, True)):
        if zoom:
            # the exact annulus; the obstacle-free grid is too coarse at this scale
            ax.add_patch(
                Wedge(
                    cmp.design.base,
                    a + b,
                    0,
                    360,
                    width=a + b - abs(a - b),
                    color="0.85",
                    zorder=0,
                )
            )
        else:
            draw_reachable(ax, task, cmp.design)
        draw_task(ax, task)
        for r in (a + b, abs(a - b)):
            ax.add_patch(
                Circle(cmp.design.base, r, fill=False, ec="k", lw=0.8, zorder=3)
            )
        ax.plot(
            cmp.points[:, 0],
            cmp.points[:, 1],
            "o",
            color="tab:blue",
            ms=4,
            zorder=6,
            label=f"{len(cmp.points)} points",
        )
        out = np.where(cmp.outside, cmp.curve.T, np.nan)
        ax.plot(
            out[0], out[1], color="tab:red", lw=3, zorder=7, label="curve outside RS"
        )
        set_limits(ax, task, cmp.design)
        if zoom:
            w = max(20 * cmp.excursion, 0.02 * task.scale)
            ax.set_xlim(worst[0] - w, worst[0] + w)
            ax.set_ylim(worst[1] - w, worst[1] + w)
            ax.set_title(
                f"zoom: up to {cmp.excursion:.2g} outside, "
                f"{100 * cmp.fraction_outside:.1f} % of the curve"
            )
            ax.locator_params(nbins=4)
        else:
            ax.legend(loc="lower right", fontsize=8)
            ax.set_title(f"discretised design: lengths {a:.3g}, {b:.3g}")
    return fig


def write_gif(
    path,
    task: TraceTask,
    design: PlanarArm,
    verification: TraceVerification,
    frames: int = 90,
    dpi: int = 80,
) -> None:
    """Animation of the arm along every primitive and transition (PillowWriter)."""
    states = np.concatenate([s.states for s in verification.segments])
    pick = np.unique(np.linspace(0, len(states) - 1, frames).round().astype(int))
    fig, ax = figures.subplots(figsize=(4.5, 4.5))
    draw_task(ax, task)
    lo, hi = _view_points(task, None)
    flat = states.reshape(-1, 2)
    lo, hi = np.minimum(lo, flat.min(0)), np.maximum(hi, flat.max(0))
    pad = 0.05 * (hi - lo).max()
    ax.set_xlim(lo[0] - pad, hi[0] + pad)
    ax.set_ylim(lo[1] - pad, hi[1] + pad)
    ax.set_title(f"{task.name}: {design.n_links} links", fontsize=9)
    (links,) = ax.plot([], [], "-o", color="k", lw=3, ms=4, zorder=6)
    (trail,) = ax.plot([], [], color="tab:blue", lw=2, zorder=5)

    def update(k):
        s = states[pick[k]]
        links.set_data(s[:, 0], s[:, 1])
        trail.set_data(states[: pick[k] + 1, -1, 0], states[: pick[k] + 1, -1, 1])
        return links, trail

    anim = FuncAnimation(fig, update, frames=len(pick), blit=True)
    anim.save(str(path), writer=PillowWriter(fps=15), dpi=dpi)
