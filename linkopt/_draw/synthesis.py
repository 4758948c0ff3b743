"""The figure of a synthesis: the traced curve of the design's cycle over the targets.
A path or a motion is drawn in the two world axes of its largest spread
(the targets and the traced positions), each target numbered in its order and joined
to the row of the cycle it is met at; a function is the output over the motor value.
The initial design's curve, when given, is drawn behind in grey."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .._engine.model import Mechanism
from . import figures, labels


def _plane(points: np.ndarray) -> tuple[int, int]:
    """The two axes of largest spread, in order."""
    spread = np.ptp(points, axis=0)
    first, second = sorted(np.argsort(spread)[-2:])
    return int(first), int(second)


def _positions(result) -> np.ndarray:
    traced = np.asarray(result.traced)
    return traced[:, :3] if traced.ndim == 2 else traced


def _curve(ax, rows: np.ndarray, solved: np.ndarray, plane, colour, label, closed):
    rows = np.where(solved[:, None], rows, np.nan)
    if closed and solved.all():
        rows = np.vstack([rows, rows[:1]])
    ax.plot(rows[:, plane[0]], rows[:, plane[1]], color=colour, lw=1.5, label=label)


def _spatial(ax, mech: Mechanism, result, initial) -> None:
    targets = result.targets
    goals = np.asarray(targets.values)[:, :3]
    traced = _positions(result)
    plane = _plane(np.vstack([goals, traced[result.solved]]))
    if initial is not None:
        _curve(ax, _positions(initial), initial.solved, plane, "0.7", "initial design",
               targets.closed)  # fmt: skip
    _curve(ax, traced, result.solved, plane, "tab:blue", "synthesised", targets.closed)
    met = traced[np.asarray(result.rows)]
    for k, (goal, at) in enumerate(zip(goals, met)):
        ax.plot([goal[plane[0]], at[plane[0]]], [goal[plane[1]], at[plane[1]]],
                color="tab:red", lw=0.8)  # fmt: skip
        ax.annotate(str(k), goal[list(plane)], fontsize=8, xytext=(3, 3),
                    textcoords="offset points")  # fmt: skip
    ax.scatter(goals[:, plane[0]], goals[:, plane[1]], color="tab:red", zorder=3,
               s=18, label=f"targets (tolerance {targets.tolerance:g})")  # fmt: skip
    unit = f" ({labels.length_unit(mech) or 'length units'})"
    ax.set_xlabel("xyz"[plane[0]] + unit)
    ax.set_ylabel("xyz"[plane[1]] + unit)
    ax.set_aspect("equal")


def _function(ax, mech: Mechanism, result, initial) -> None:
    targets = result.targets
    motors = np.asarray(result.motors)[:, 0]
    if initial is not None:
        ax.plot(motors, np.where(initial.solved, initial.traced, np.nan), color="0.7",
                label="initial design")  # fmt: skip
    ax.plot(motors, np.where(result.solved, result.traced, np.nan), color="tab:blue",
            label="synthesised")  # fmt: skip
    label = f"targets (tolerance {targets.tolerance:g})"
    ax.scatter(np.asarray(targets.motors)[:, 0], targets.values, color="tab:red",
               zorder=3, s=18, label=label)  # fmt: skip
    ax.set_xlabel(f"motor {mech.motor_names[0]}")
    ax.set_ylabel(f"output {targets.name}")


def plot_synthesis(mech: Mechanism, result, path: str | Path, initial=None) -> Path:
    """Draw ``result`` (a :class:`linkopt._synth.run.SynthesisResult`) to ``path``
    (PNG); ``initial`` a result of the file's design, drawn behind."""
    fig, ax = figures.subplots(figsize=(6.4, 5.2), constrained_layout=True)
    if result.targets.kind == "function":
        _function(ax, mech, result, initial)
    else:
        _spatial(ax, mech, result, initial)
    ax.set_title(
        f"{mech.name}: {result.targets.kind} of {result.targets.name} "
        f"(RMS {result.rms:.3g}, max {result.max_distance:.3g})"
    )
    ax.legend(loc="best", fontsize=8)
    path = Path(path)
    fig.savefig(path, dpi=100)
    return path


#: Frames of the synthesis animation (``synthesis.gif``): the cycle's rows, evenly.
ANIMATION_FRAMES = 72


def cycle_frames(result, frames: int = ANIMATION_FRAMES) -> np.ndarray:
    """The motor rows ``(T, M)`` of the animation: ``frames`` rows of the result's
    swept cycle, evenly spaced, the first and last included (all when fewer)."""
    motors = np.asarray(result.motors)
    count = min(frames, len(motors))
    return motors[np.round(np.linspace(0, len(motors) - 1, count)).astype(int)]


def _traced_as(mech: Mechanism, item, result):
    """The motion with the synthesised point as its only trace (a path target); the
    motion's own traces otherwise."""
    import dataclasses

    if result.targets.kind != "path":
        return item
    k = mech.point_names.index(result.targets.name)
    return dataclasses.replace(
        item, trace=item.points[:, [k]], trace_names=(result.targets.name,)
    )


def _targets_on(ax, result, basis) -> None:
    """The path or motion targets (their positions) as static red dots, in the
    animation's plane (``basis``) or its 3-D view (None)."""
    if result.targets.kind == "function":
        return
    goals = np.asarray(result.targets.values)[:, :3]
    label = f"targets (tolerance {result.targets.tolerance:g})"
    if basis is None:
        ax.scatter(*goals.T, color="tab:red", s=14, depthshade=False, label=label)
    else:
        goals = goals @ np.asarray(basis).T
        ax.scatter(*goals.T, color="tab:red", s=14, zorder=3, label=label)


def animate_synthesis(
    mech: Mechanism, result, path: str | Path, frames: int = ANIMATION_FRAMES
) -> Path:
    """``path`` (a GIF): the synthesised design moving through its cycle
    (:func:`cycle_frames`, solved by continuation from the rest pose), the traced
    point's path growing frame by frame over the targets; bodies coloured by
    ``f_sing`` as every linkopt animation is (:func:`linkopt._draw.animation.draw`)."""
    from .._design.motion import motion
    from .animation import draw

    design = np.asarray(result.design)
    rows = cycle_frames(result, frames)
    item = _traced_as(mech, motion(mech, design=design, motors=rows), result)
    return draw(
        mech,
        item,
        path,
        design=design,
        title=f"{mech.name}: {result.targets.kind} of {result.targets.name}",
        decorate=lambda ax, basis: _targets_on(ax, result, basis),
    )
