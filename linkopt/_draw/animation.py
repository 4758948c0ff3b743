"""Animations of a mechanism moving along a path, drawn as a GIF (beyond the paper;
``linkopt animate`` and an optimisation run's ``motion_*.gif``). The frames, the path
and the default loop are :mod:`linkopt._design.motion`'s.

A planar mechanism (:func:`linkopt._draw.planar.plane_normal`, the test the
mechanism figure uses too: a prismatic axis in the plane keeps it planar) is drawn in
its plane (the world axes' names when the plane is a coordinate plane),
others in a fixed 3-D view. Each moving body is the outline of the convex hull of its
joint anchors and named points in their best-fit plane (a segment when they are
collinear; members inside the hull are not on it), all bodies coloured by the
frame's ``f_sing`` on the maps' scale (viridis, log, brighter = closer to a
singularity; :func:`linkopt._draw.space_plots._colour_norm`'s bounds over the
frames unless ``f_sing_range`` is given); the ground's joints are triangles, the
motors' joints squares, and the traced points' paths grow frame by frame. The
traced points are the points of the position outputs (reported ones too), or every
named point when all outputs are angles
(:func:`linkopt._design.motion.traced_points`).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import partial
from pathlib import Path

import matplotlib
import numpy as np
from jaxtyping import Float
from matplotlib.collections import LineCollection
from matplotlib.colors import LogNorm

from .._design.motion import (
    DEFAULT_FRAMES,
    Motion,
    PathNotReached,
    motion,
    unreached_message,
)
from .._design.outputs import writing
from .._engine.model import Mechanism
from . import figures
from .planar import plane_basis

#: Frames per second of the GIF.
FPS = 15
MAGENTA = "#ff00ff"


def colour_norm(values: Float[np.ndarray, " T"], f_sing_range=None) -> LogNorm:
    """The maps' log scale (:func:`linkopt._draw.space_plots._colour_norm`) over
    ``values``, or over ``f_sing_range`` ``(low, high)`` when given."""
    if f_sing_range is not None:
        low, high = (float(v) for v in f_sing_range)
        return LogNorm(vmin=max(low, 1e-3), vmax=max(high, low * 1.01, 1e-3 * 1.01))
    values = np.asarray(values)[np.isfinite(values)]
    low = max(float(np.min(values)), 1e-3)
    return LogNorm(vmin=low, vmax=max(float(np.percentile(values, 99)), low * 10))


def _members(mech: Mechanism, body: int) -> np.ndarray:
    """Indices into ``[joints, points]`` of a body's joints and named points."""
    joints = [int(k) for k in mech.joints_on(body)]
    points = [
        len(mech.joint_names) + k
        for k in range(len(mech.point_names))
        if mech.point_bodies[k] == body
    ]
    return np.array(joints + points, dtype=int)


#: Spread (relative to the largest) below which a body's members count as collinear.
COLLINEAR_TOL = 1e-9


def body_outline(members: np.ndarray, coords: Float[np.ndarray, "N 3"]) -> np.ndarray:
    """``members`` (indices of ``coords``' rows) on the outline of their convex hull
    in their best-fit plane, counter-clockwise and closed; the two extreme members
    along their line when they are collinear. Members inside the hull (a platform's
    centre point) are left out, so a body reads as its plate, not a ring through an
    interior point."""
    centred = coords - coords.mean(axis=0)
    _, spread, vt = np.linalg.svd(centred, full_matrices=False)
    if len(spread) < 2 or spread[1] <= COLLINEAR_TOL * max(spread[0], 1e-300):
        along = centred @ vt[0]
        return members[[int(np.argmin(along)), int(np.argmax(along))]]
    from scipy.spatial import ConvexHull

    flat = centred @ vt[:2].T
    hull = ConvexHull(flat).vertices  # counter-clockwise in 2-D
    return np.append(members[hull], members[hull[0]])


def body_rings(mech: Mechanism, rest: Float[np.ndarray, "X 3"]) -> list[np.ndarray]:
    """Per moving body, the outline of its members (:func:`_members`) at ``rest``
    (:func:`body_outline`): a segment for a bar, a closed polygon for a plate."""
    rings = []
    for body in range(mech.num_bodies):
        members = _members(mech, body)
        if body == mech.ground or len(members) < 2:
            continue
        rings.append(body_outline(members, rest[members]))
    return rings


@dataclass(frozen=True)
class _Scene:
    """The artists a frame updates (drawn over a background rendered once)."""

    links: object  # LineCollection or Line3DCollection
    joints: object
    motors: object
    traces: list
    label: object

    def artists(self) -> list:
        return [self.links, *self.traces, self.joints, self.motors, self.label]


def _project(xyz: np.ndarray, basis) -> np.ndarray:
    return xyz if basis is None else xyz @ basis.T


def _limits(ax, coords: np.ndarray, basis) -> None:
    """Equal-aspect limits around every frame's coordinates, padded 8 %."""
    low, high = coords.min(axis=0), coords.max(axis=0)
    centre, half = (low + high) / 2, 0.54 * max(float(np.max(high - low)), 1e-9)
    ax.set_xlim(centre[0] - half, centre[0] + half)
    ax.set_ylim(centre[1] - half, centre[1] + half)
    if basis is None:
        ax.set_zlim(centre[2] - half, centre[2] + half)
        ax.set_box_aspect((1, 1, 1))
    else:
        ax.set_aspect("equal")


def _world_axis(direction: np.ndarray) -> int | None:
    """The world axis ``direction`` is, or None."""
    k = int(np.argmax(np.abs(direction)))
    return k if abs(direction[k]) == 1.0 else None


def _axis_labels(ax, mech: Mechanism, basis) -> None:
    unit = mech.raw.get("mechanism", {}).get("units", "")
    unit = f" ({unit})" if isinstance(unit, str) and unit else ""
    if basis is None:
        ax.set_xlabel("x" + unit), ax.set_ylabel("y" + unit), ax.set_zlabel("z" + unit)
        return
    for set_label, direction, other in zip(
        (ax.set_xlabel, ax.set_ylabel), basis, ("u", "v")
    ):
        k = _world_axis(direction)
        set_label(("xyz"[k] if k is not None else f"{other} (in the plane)") + unit)


def target_box(ax, mech: Mechanism, basis) -> None:
    """The target range of the position outputs, where exactly two outputs are
    positions, of one point, and they are the drawing plane's two coordinates (in
    either order; other outputs, an angle of a planar platform say, are not drawn)."""
    if basis is None:
        return
    positions = [k for k, kind in enumerate(mech.output_kinds) if kind == "position"]
    if len(positions) != 2 or len(set(mech.output_points[positions])) != 1:
        return
    axes = [_world_axis(b) for b in basis]
    coords = [int(mech.output_coords[k]) for k in positions]
    if sorted(coords) != sorted(a for a in axes if a is not None) or None in axes:
        return
    first, second = (positions[coords.index(a)] for a in axes)  # drawing order
    lo, hi = mech.output_min, mech.output_max
    ax.plot(
        [lo[first], hi[first], hi[first], lo[first], lo[first]],
        [lo[second], lo[second], hi[second], hi[second], lo[second]],
        color=MAGENTA,
        lw=1.0,
        ls="--",
        label="target range",
    )


def _empty_line(ax, basis, style: str, **kwargs):
    empty = [[]] * (2 if basis is not None else 3)
    return ax.plot(*empty, style, animated=True, **kwargs)[0]


def _scene(ax, mech: Mechanism, item: Motion, basis) -> _Scene:
    """The frame artists (animated, empty) and the static ones: the ground's joints
    and the target box."""
    from mpl_toolkits.mplot3d.art3d import Line3DCollection

    ground = [k for k, (i, j) in enumerate(mech.joint_bodies) if mech.ground in (i, j)]
    fixed = _project(item.joints[0, ground], basis)
    ax.plot(*fixed.T, "^", color="0.45", ms=9, ls="none", label="ground joints")
    target_box(ax, mech, basis)
    collection = LineCollection if basis is not None else Line3DCollection
    links = collection([], linewidths=3, animated=True)
    ax.add_collection(links)
    traces = [
        _empty_line(ax, basis, "-", color=MAGENTA, lw=1.5) for _ in item.trace_names
    ]
    if traces:
        traces[0].set_label("path of " + ", ".join(item.trace_names))
    return _Scene(
        links=links,
        joints=_empty_line(ax, basis, "o", ms=4, mfc="white", mec="k"),
        motors=_empty_line(ax, basis, "s", ms=8, mfc="none", mec="k", mew=1.5),
        traces=traces,
        label=ax.figure.text(0.02, 0.02, "", fontsize=8, animated=True),
    )


def _set(line, coords: np.ndarray) -> None:
    if coords.shape[-1] == 3:
        line.set_data_3d(coords[:, 0], coords[:, 1], coords[:, 2])
    else:
        line.set_data(coords[:, 0], coords[:, 1])


def _update(k: int, scene: _Scene, mech, item: Motion, rings, basis, norm) -> None:
    """Move the frame artists to frame ``k``."""
    every = _project(np.concatenate([item.joints[k], item.points[k]]), basis)
    scene.links.set_segments(
        [every[[r[i], r[i + 1]]] for r in rings for i in range(len(r) - 1)]
    )
    scene.links.set_color(matplotlib.colormaps["viridis"](norm(item.f_sing[k])))
    _set(scene.joints, every[: len(mech.joint_names)])
    _set(scene.motors, every[mech.motor_joints])
    for q, line in enumerate(scene.traces):
        _set(line, _project(item.trace[: k + 1, q], basis))
    short = "" if item.reached[k] else "   (out of reach)"
    scene.label.set_text(
        f"frame {k + 1}/{len(item.states)}   f_sing = {item.f_sing[k]:.3g}{short}"
    )


def _figure(mech: Mechanism, item: Motion, basis, norm, title: str, dpi: int):
    fig = figures.figure(figsize=(4.6, 4.0), dpi=dpi)
    ax = fig.add_subplot(111, projection=None if basis is not None else "3d")
    if basis is None:
        ax.view_init(elev=25, azim=-60)
    every = np.concatenate([item.joints, item.points], axis=1).reshape(-1, 3)
    _limits(ax, _project(every, basis), basis)
    _axis_labels(ax, mech, basis)
    ax.tick_params(labelsize=7)
    mappable = matplotlib.cm.ScalarMappable(norm=norm, cmap="viridis")
    bar = fig.colorbar(mappable, ax=ax, shrink=0.8, pad=0.12 if basis is None else 0.04)
    bar.set_label("f_sing (brighter = closer to a singularity)", fontsize=7)
    bar.ax.tick_params(labelsize=7)
    fig.suptitle(title or mech.name, fontsize=9)
    return fig, ax


def _render(fig, scene: _Scene, update, frames: int) -> list:
    """Each frame as a Pillow image: the static background is drawn once, the frame
    artists over a copy of it (blitting)."""
    from PIL import Image

    canvas = fig.canvas
    canvas.draw()
    background = canvas.copy_from_bbox(fig.bbox)
    images = []
    for k in range(frames):
        update(k)
        canvas.restore_region(background)
        for artist in scene.artists():
            if hasattr(artist, "do_3d_projection"):
                artist.do_3d_projection()
            fig.draw_artist(artist)
        rgba = np.asarray(canvas.buffer_rgba())
        images.append(Image.fromarray(rgba[..., :3].copy()))
    return images


def quantised(images: list) -> list:
    """Each frame in palette mode by Pillow's fast octree quantiser (256 colours, no
    dithering). Pillow would otherwise quantise each RGB frame by median cut while
    saving, most of the time of writing a GIF; the octree is several times faster and
    on the five-bar's loop keeps every pixel within a few levels of the rendered
    colour, where median cut merges rare colours (the colour bar's ends, thin
    lines)."""
    from PIL import Image

    return [im.quantize(256, method=Image.Quantize.FASTOCTREE) for im in images]


def draw(
    mech: Mechanism,
    item: Motion,
    path: str | Path,
    *,
    design=None,
    f_sing_range=None,
    title: str = "",
    dpi: int = 72,
    decorate=None,
) -> Path:
    """Write ``item``'s frames (all reached, unless it is the default loop) as a
    looping GIF, ``FPS`` frames a second (matplotlib Agg frames, written by Pillow;
    module docstring). ``decorate(ax, basis)``, when given, draws static artists
    (a synthesis's targets) on the axes before the frames; ``basis`` is the plane's
    ``(2, 3)`` basis, None for a 3-D view."""
    if item.first_unreached is not None and not item.default:
        raise PathNotReached(unreached_message(mech, item), item.first_unreached + 1)
    basis = plane_basis(mech, design)
    norm = colour_norm(item.f_sing, f_sing_range)
    rings = body_rings(mech, np.concatenate([item.joints[0], item.points[0]]))
    fig, ax = _figure(mech, item, basis, norm, title, dpi)
    scene = _scene(ax, mech, item, basis)
    if decorate is not None:
        decorate(ax, basis)
    if basis is not None:
        ax.legend(loc="best", fontsize=6, framealpha=0.6)
    images = _render(
        fig,
        scene,
        lambda k: _update(k, scene, mech, item, rings, basis, norm),
        len(item.states),
    )
    path = Path(path)
    images = quantised(images)
    images[0].save(
        path,
        format="GIF",
        save_all=True,
        append_images=images[1:],
        duration=round(1000 / FPS),
        loop=0,
    )
    return path


def animate(
    mech: Mechanism,
    path: str | Path,
    *,
    design=None,
    frames: int = DEFAULT_FRAMES,
    motors=None,
    outputs=None,
    f_sing_range=None,
    title: str = "",
) -> Motion:
    """A GIF at ``path`` of the mechanism along ``motors`` or ``outputs`` rows (one
    frame each) or the default loop in ``frames`` frames (:func:`motion`); returns the
    frames. For given rows, :class:`PathNotReached` naming the first unreached row
    (1-based) when one is not on the rest pose's branch, and nothing is written; the
    default loop is drawn also where it is out of reach (module docstring)."""
    item = motion(mech, design=design, frames=frames, motors=motors, outputs=outputs)
    draw(mech, item, path, design=design, f_sing_range=f_sing_range, title=title)
    return item


def write_run_motions(
    initial: Mechanism, current: Mechanism, out: Path, design, frames=DEFAULT_FRAMES
) -> list[str]:
    """``motion_initial.gif`` (``initial``, its file's design) and
    ``motion_optimized.gif`` (``design``, along the default loop through the targets
    of ``current``, the run's mechanism) in ``out``, on one colour scale
    (:func:`run_motion_drawings`, drawn here); returns the names written."""
    drawings = run_motion_drawings(initial, current, out, design, frames)
    for drawing in drawings:
        drawing()
    return [drawing.args[0] for drawing in drawings]


def run_motion_drawings(
    initial: Mechanism, current: Mechanism, out: Path, design, frames=DEFAULT_FRAMES
) -> tuple[partial, ...]:
    """The motions of :func:`write_run_motions`, solved, and their GIFs left to draw:
    one picklable call per file (``motion_initial.gif``, then
    ``motion_optimized.gif``), each naming its file in an error
    (:func:`linkopt._design.run.writing`). Both motions are solved with ``initial``,
    so they share its compiled programs (:func:`motion`), and before either is drawn,
    as their colour scale is over both; the drawings are then independent, so two
    processes can draw one each (:func:`linkopt._design.run.write_outputs`)."""
    items = {
        "motion_initial.gif": (initial, None, "initial design"),
        "motion_optimized.gif": (initial, design, "optimised design"),
    }
    loops = {"motion_initial.gif": initial, "motion_optimized.gif": current}
    motions = {
        name: motion(m, design=d, frames=frames, loop_of=loops[name])
        for name, (m, d, _) in items.items()
    }
    norm = colour_norm(np.concatenate([m.f_sing for m in motions.values()]))
    return tuple(
        partial(
            _draw_file,
            name,
            m,
            motions[name],
            out / name,
            d,
            (norm.vmin, norm.vmax),
            f"{m.name}, {label}",
        )
        for name, (m, d, label) in items.items()
    )


def _draw_file(name: str, mech, item, path, design, f_sing_range, title) -> None:
    """:func:`draw` of one file of :func:`run_motion_drawings`, an error naming it."""
    with writing(name):
        draw(mech, item, path, design=design, f_sing_range=f_sing_range, title=title)
