"""Headless 3-D figures of arm designs: the arm at every target with the tool's path and
the obstacles (paper 000, Figs. 3 and 6), and the joint-elimination sequence
(Fig. 9)."""

from __future__ import annotations

from functools import partial
from pathlib import Path

import jax
import jax.numpy as jnp
import matplotlib
import numpy as np

from ..._arms.codesign.model import Arm, arm_state
from ..._arms.codesign.sdf import Obstacle
from ..._config import jit
from ..._engine.constraints import homogenised_point_positions
from .. import figures

COLOURS = matplotlib.colormaps["rainbow"]


@partial(jit, static_argnums=0)
def module_points(arm: Arm, theta, d):
    """Module-end points and tip of every configuration ``(W, n)`` ->
    ``(W, K + 1, 3)``."""

    def one(th):
        geom, state = arm_state(arm, th, d)
        return (
            homogenised_point_positions(arm.mechanism, geom, state)
            * arm.mechanism.length_scale
        )

    return jax.vmap(one)(theta)


def _box_edges(center, size, orientation=None):
    unit = np.array(
        [[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)],
        dtype=float,
    )
    pairs = [
        (a, b)
        for a in range(8)
        for b in range(a + 1, 8)
        if np.sum(unit[a] != unit[b]) == 1
    ]
    corners = unit * 0.5 * np.asarray(size)
    if orientation is not None:
        corners = corners @ np.asarray(orientation).T
    corners = corners + np.asarray(center)
    return [(corners[a], corners[b]) for a, b in pairs]


def draw_obstacle(ax, obstacle: Obstacle, limits) -> None:
    style = {"color": "0.45", "linewidth": 0.8}
    if obstacle.kind == "box" and obstacle.orientation is not None:
        for a, b in _box_edges(obstacle.center, obstacle.size, obstacle.orientation):
            ax.plot(*zip(a, b), **style)
    elif obstacle.kind == "box":
        lo, hi = limits
        half = 0.5 * np.asarray(
            obstacle.size
        )  # huge boxes (the ground) clipped to the view
        low = np.maximum(np.asarray(obstacle.center) - half, lo)
        high = np.minimum(np.asarray(obstacle.center) + half, hi)
        if np.all(high > low):
            for a, b in _box_edges(0.5 * (low + high), high - low):
                ax.plot(*zip(a, b), **style)
    elif obstacle.kind in ("sphere", "capsule"):
        u, v = np.meshgrid(np.linspace(0, 2 * np.pi, 16), np.linspace(0, np.pi, 9))
        ball = (
            np.stack([np.cos(u) * np.sin(v), np.sin(u) * np.sin(v), np.cos(v)], axis=-1)
            * obstacle.radius
        )
        centres = (
            [obstacle.center] if obstacle.kind == "sphere" else [obstacle.a, obstacle.b]
        )
        for c in centres:
            ax.plot_wireframe(*(ball + np.asarray(c)).transpose(2, 0, 1), **style)
        if obstacle.kind == "capsule":
            ax.plot(*zip(obstacle.a, obstacle.b), color="0.45", linewidth=3)


def _limits(points: np.ndarray, targets: np.ndarray, pad: float = 0.1):
    every = np.concatenate([points.reshape(-1, 3), targets])
    lo, hi = every.min(axis=0) - pad, every.max(axis=0) + pad
    span = (hi - lo).max()
    mid = 0.5 * (lo + hi)
    return mid - span / 2, mid + span / 2


def draw_solution(
    ax,
    arm: Arm,
    theta,
    design,
    targets: np.ndarray,
    target_waypoints,
    axes=None,
    obstacles=(),
    title: str = "",
) -> None:
    """The arm at each target (one colour per target), the tip path (dashed) and
    obstacles."""
    points = np.asarray(module_points(arm, jnp.asarray(theta), jnp.asarray(design)))
    lo, hi = _limits(points, targets)
    for obstacle in obstacles:
        draw_obstacle(ax, obstacle, (lo, hi))
    ax.plot(*points[:, -1].T, "k--", linewidth=0.8)
    for i, w in enumerate(target_waypoints):
        colour = COLOURS(i / max(len(target_waypoints) - 1, 1))
        ax.plot(*points[w].T, "-o", color=colour, markersize=2.5, linewidth=2)
        ax.scatter(*targets[i], marker="x", color=colour, s=30)
        if axes is not None and np.any(axes[i]):
            ax.quiver(*targets[i], *(0.08 * axes[i]), color=colour, linewidth=1)
    ax.set_xlim(lo[0], hi[0])
    ax.set_ylim(lo[1], hi[1])
    ax.set_zlim(lo[2], hi[2])
    ax.set_xlabel("x")
    ax.set_ylabel("y")
    ax.set_zlabel("z")
    ax.set_title(title, fontsize=9)


def plot_solution(problem, solution, path: str | Path, title: str = "") -> Path:
    """Figure of one solved problem (:mod:`linkopt._arms.codesign.nlp`) as PNG."""
    fig = figures.figure(figsize=(7, 6))
    ax = fig.add_subplot(projection="3d")
    draw_solution(
        ax,
        problem.arm,
        solution.theta,
        solution.design,
        problem.target_position,
        problem.target_waypoints,
        problem.target_axis,
        problem.task.obstacles,
        title,
    )
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    return Path(path)


def plot_stages(stages, path: str | Path) -> Path:
    """The elimination sequence: the optimised arm of every stage, side by side."""
    fig = figures.figure(figsize=(4.2 * len(stages), 4.4))
    for k, stage in enumerate(stages):
        ax = fig.add_subplot(1, len(stages), k + 1, projection="3d")
        sol, prob = stage.solution, stage.problem
        n = prob.arm.num_joints
        joints = f"{n} joint{'s' if n != 1 else ''}"
        label = f"{joints}, {'feasible' if sol.feasible else 'infeasible'}"
        if stage.elimination is not None:
            merged = stage.elimination.candidate + 1
            label += (
                f"\nmerged {merged}+{merged + 1}, δ = {stage.elimination.delta:.2g}"
            )
        draw_solution(
            ax,
            prob.arm,
            sol.theta,
            sol.design,
            prob.target_position,
            prob.target_waypoints,
            prob.target_axis,
            prob.task.obstacles,
            label,
        )
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    return Path(path)
