"""The drawing of a DH synthesis: the task points and the arm at a few targets (PNG,
headless matplotlib)."""

from __future__ import annotations

from pathlib import Path

import matplotlib
import numpy as np

from ..._arms.dh import table as dh
from ..._arms.dh.synthesis import DHSynthesis
from .. import figures


def draw(
    synthesis: DHSynthesis, path: str | Path, count: int = 4, title: str = ""
) -> Path:
    """PNG of the task points and the arm (links through the DH frame origins) at
    ``count`` targets spread over the list; headless matplotlib."""
    fig = figures.figure(figsize=(7, 6))
    ax = fig.add_subplot(projection="3d")
    pts = synthesis.targets
    ax.scatter(
        *pts.T,
        c=synthesis.manipulability,
        cmap="viridis",
        s=14,
        label="task points (colour = w)",
    )
    drawn = [pts, np.zeros((1, 3)), *_draw_poses(ax, synthesis, count)]
    ax.scatter([0], [0], [0], marker="s", s=60, color="k", label="base (frame 0)")
    _equal_axes(ax, np.concatenate(drawn))
    ax.set_xlabel("x")
    ax.set_ylabel("y")
    ax.set_zlabel("z")
    ax.set_title(title or _default_title(synthesis), fontsize=10)
    ax.legend(fontsize=7, loc="upper left")
    fig.tight_layout()
    path = Path(path)
    fig.savefig(path, dpi=110)
    return path


def _draw_poses(ax, synthesis: DHSynthesis, count: int) -> list[np.ndarray]:
    """The arm at ``count`` targets spread over the list; returns the frame origins
    drawn."""
    types, table = synthesis.types, synthesis.table
    pts = synthesis.targets
    picks = np.unique(
        np.linspace(0, len(pts) - 1, min(count, len(pts))).round().astype(int)
    )
    drawn = []
    for k, i in enumerate(picks):
        origins = np.asarray(dh.frames_and_jacobian(types, table, synthesis.q[i])[0])[
            :, :3, 3
        ]
        drawn.append(origins)
        ax.plot(
            *origins.T,
            "-o",
            lw=2.5,
            ms=4,
            color=matplotlib.colormaps["tab10"](k),
            label=f"target {i}: w = {synthesis.manipulability[i]:.3f}",
        )
    return drawn


def _default_title(synthesis: DHSynthesis) -> str:
    w = synthesis.manipulability
    return (
        f"{synthesis.types}: mean w {np.mean(w):.3f}, min {np.min(w):.3f}, "
        f"size {synthesis.size:.3f}"
    )


def _equal_axes(ax, points: np.ndarray) -> None:
    """Same scale on x, y and z (a cube around everything drawn)."""
    centre, half = (
        (points.max(axis=0) + points.min(axis=0)) / 2,
        (points.max(axis=0) - points.min(axis=0)).max() / 2 or 1.0,
    )
    for setter, c in zip((ax.set_xlim, ax.set_ylim, ax.set_zlim), centre):
        setter(c - half, c + half)
    ax.set_box_aspect((1, 1, 1))
