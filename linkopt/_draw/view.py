"""The browser view: one self-contained HTML page that moves a mechanism through its
precomputed configurations (:mod:`linkopt._design.view_grid`).

Why plotly: its Python package carries plotly.js (4.8 MB), which the page inlines, so
the file opens offline in any browser with nothing else installed and nothing served;
a local viewer process (viser) would need Python running beside the browser and the
page could not be sent to someone. WebGL 3D scenes (turn, zoom), sliders and heatmaps
are built in.

What the page holds per design: the motor grid's axes, each reached cell's state
(homogenised, nine significant digits; a failed cell holds none), ``f_sing`` and the
least clearance; per body its capsules and joints in its own frame, and the named
points in theirs. The page poses the bodies of a cell's state itself (a quaternion
rotation per body), so it needs no Python. Colours are the maps' (:mod:`.space_plots`
of the design layer): ``f_sing`` viridis on a log scale from its least value (at least
1e-3) to its 99th percentile, failed cells black; the clearance red-white-blue,
white at the file's ``[collision] clearance``. The target range of the outputs that
are a point's coordinates is a magenta box (coordinates that no output bounds span the
point's trace). A file with a ``[synthesis]`` path or motion also shows, per design,
the target positions (numbered in order) and the curve its whole cycle traces.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .._engine.model import Mechanism
from .._engine.welding import part_state, parts
from .._export.tree import body_capsules, default_thickness, rest
from .._folders import write_atomic
from .view_page import page

#: Body colours, cycled (plotly's D3 palette).
PALETTE = (
    "#1f77b4",
    "#ff7f0e",
    "#2ca02c",
    "#d62728",
    "#9467bd",
    "#8c564b",
    "#e377c2",
    "#7f7f7f",
    "#bcbd22",
    "#17becf",
)


@dataclass(frozen=True)
class Shown:
    """One design of a page: its label, design vector and solved grid
    (:class:`linkopt._design.view_grid.ViewGrid`)."""

    label: str
    design: np.ndarray | None
    grid: object


def _number(value: float) -> float | None:
    """``value`` rounded to nine significant digits; None for NaN."""
    return None if not np.isfinite(value) else float(f"{value:.9g}")


def _numbers(values) -> list:
    return [_number(float(v)) for v in np.ravel(values)]


def _bodies(mech: Mechanism, design) -> list[dict]:
    """Per part its name, colour, capsule radius, and its capsules (``[a, b]``) and
    joints in its own frame (file units)."""
    whole = parts(mech)
    rest_pose = rest(whole, design)
    thickness = default_thickness(whole) if whole.collision is None else None
    out = []
    for b, name in enumerate(whole.body_names):
        origin = rest_pose.origins[b]
        capsules = body_capsules(whole, rest_pose, b, thickness)
        joints = rest_pose.anchors[whole.joints_on(b)] - origin
        out.append(
            {
                "name": name,
                "colour": PALETTE[b % len(PALETTE)],
                "radius": _number(max(r for _, _, r in capsules)),
                "capsules": [
                    _numbers(np.concatenate([a - origin, e - origin]))
                    for a, e, _ in capsules
                ],
                "joints": [_numbers(j) for j in joints],
            }
        )
    return out


def _points(mech: Mechanism, design) -> list[dict]:
    whole = parts(mech)
    rest_pose = rest(whole, design)
    return [
        {
            "name": name,
            "body": int(whole.point_bodies[k]),
            "local": _numbers(
                rest_pose.points[k] - rest_pose.origins[whole.point_bodies[k]]
            ),
        }
        for k, name in enumerate(whole.point_names)
    ]


def _curve(mech: Mechanism, design) -> dict | None:
    """A file with a ``[synthesis]`` path or motion: its target positions, numbered in
    order, and the curve the design's whole cycle traces (the dense cycle sweep of
    :mod:`linkopt._synth.cycle`; an unsolved step is a gap). None for another file, and
    for a function target (an output against a motor value, drawn by
    ``linkopt synthesize``'s figure, not in space)."""
    if "synthesis" not in mech.raw:
        return None
    from .._synth.cycle import sweep_cycle
    from .._synth.targets import load_targets

    targets = load_targets(mech)
    if targets.kind not in ("path", "motion"):
        return None
    design = mech.design.p0 if design is None else np.asarray(design)
    report = sweep_cycle(mech, design, targets)
    return {
        "kind": targets.kind,
        "name": targets.name,
        "targets": [_numbers(v[:3]) for v in targets.values],
        "traced": [
            _numbers(row[:3]) if ok else None
            for row, ok in zip(report.traced, report.solved)
        ],
        "defect": report.defect,
    }


def _design_data(mech: Mechanism, shown: Shown) -> dict:
    grid = shown.grid
    states = part_state(mech, grid.states)
    return {
        "label": shown.label,
        "axes": [_numbers(ax) for ax in grid.axes],
        "rest_cell": grid.rest_cell,
        "states": [_numbers(s) if ok else None for s, ok in zip(states, grid.feasible)],
        "f_sing": _numbers(grid.f_sing),
        "clearance": None if grid.clearance is None else _numbers(grid.clearance),
        "bodies": _bodies(mech, shown.design),
        "points": _points(mech, shown.design),
        "curve": _curve(mech, shown.design),
    }


def _f_sing_scale(shown: list[Shown]) -> dict:
    """The maps' log scale (module docstring), as log10 bounds."""
    values = np.concatenate([s.grid.f_sing[s.grid.feasible] for s in shown])
    if not values.size:
        return {"low": -3.0, "high": 0.0}
    low = max(float(np.min(values)), 1e-3)
    high = max(float(np.percentile(values, 99)), float(np.min(values)) * 10, low * 10)
    return {"low": float(np.log10(low)), "high": float(np.log10(high))}


def _clearance_scale(mech: Mechanism, shown: list[Shown]) -> dict | None:
    """White at the file's clearance band, symmetric about it; None without a finite
    clearance."""
    values = [s.grid.clearance for s in shown if s.grid.clearance is not None]
    values = np.concatenate(values) if values else np.zeros(0)
    values = values[np.isfinite(values)]
    if not values.size:
        return None
    band = float(mech.collision.clearance)
    half = max(float(np.max(np.abs(values - band))), 1e-9 * band)
    return {"band": band, "low": band - half, "high": band + half}


def _target(mech: Mechanism) -> dict | None:
    """The target range of the outputs that are one point's coordinates: the point's
    name and per axis ``[low, high]`` (None where no output bounds the axis)."""
    rows = [k for k, kind in enumerate(mech.output_kinds) if kind == "position"]
    if not rows:
        return None
    point = int(mech.output_points[rows[0]])
    box: list = [None, None, None]
    for k in rows:
        if int(mech.output_points[k]) == point:
            box[int(mech.output_coords[k])] = [
                float(mech.output_min[k]),
                float(mech.output_max[k]),
            ]
    return {"point": mech.point_names[point], "box": box}


def view_data(mech: Mechanism, shown: list[Shown]) -> dict:
    """Everything the page draws (module docstring), as JSON-ready values."""
    unit = mech.raw.get("mechanism", {}).get("units", "")
    return {
        "name": mech.name,
        "units": unit if isinstance(unit, str) else "",
        "length_scale": float(mech.length_scale),
        "motors": [
            {"name": n, "linear": bool(lin)}
            for n, lin in zip(mech.motor_names, mech.motor_linear)
        ],
        "f_sing_scale": _f_sing_scale(shown),
        "clearance_scale": _clearance_scale(mech, shown),
        "target": _target(mech),
        "designs": [_design_data(mech, s) for s in shown],
    }


def view_html(mech: Mechanism, shown: list[Shown]) -> str:
    """The self-contained page (plotly.js inlined) of ``shown``'s designs."""
    from plotly.offline import get_plotlyjs

    data = json.dumps(view_data(mech, shown), separators=(",", ":"), allow_nan=False)
    return page(get_plotlyjs(), data, mech.name)


def write_view(mech: Mechanism, shown: list[Shown], path) -> int:
    """Write the page to ``path``; returns its size in bytes."""
    text = view_html(mech, shown)
    write_atomic(Path(path), text)
    return len(text.encode("utf-8"))


def write_page(mech, designs, out: Path, resolution, progress=None) -> dict:
    """Solve each design's grid and write the page; returns a summary."""
    from .._design.view_grid import check_view_grid, view_grid

    resolution = check_view_grid(mech, resolution, len(designs))
    shown = []
    for label, design in designs:
        if progress is not None:
            progress(f"solving {resolution}^{mech.num_motors} configurations: {label}")
        shown.append(Shown(label, design, view_grid(mech, resolution, design)))
    size = write_view(mech, shown, out)
    return {
        "out": str(out),
        "bytes": size,
        "resolution": resolution,
        "cells": int(len(shown[0].grid.feasible)),
        "reached": {s.label: int(np.count_nonzero(s.grid.feasible)) for s in shown},
    }
