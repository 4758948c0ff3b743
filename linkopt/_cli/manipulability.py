"""``linkopt arm manipulability POINTS --joints RRR|N --out DIR``: DH synthesis
(paper 004).

Writes ``DIR/dh.json`` (the DH table in the distal convention, per target the joint
values, residual and manipulability measured on the engine's Mechanism),
``DIR/arm.toml`` (the equivalent mechanism file, accepted by ``linkopt check`` / ``fk``)
and ``DIR/manipulability.png`` (the arm at a few targets with the point cloud). Progress
lines go to stderr; the summary to stdout.

Exit status: 0 when every target is reached (residual on the engine's mechanism within
the reach tolerance, 1e-3), 1 when some are not or an engine FK solve fails (the files
are still written), 2 on bad input (one ``linkopt: error: ...`` line on stderr).
"""

from __future__ import annotations

import json
import re
import sys
from pathlib import Path

import numpy as np

from .._arms import checks
from .._arms.dh import table as dh
from .._arms.dh.synthesis import (
    DHSynthesis,
    DHSynthesisSettings,
    configurations,
    engine_report,
    rest_configuration,
    synthesize_dh,
)
from .._errors import InputError

CONVENTION = "A_i = Rot_z(theta_i) Trans_z(d_i) Trans_x(a_i) Rot_x(alpha_i) (standard, distal DH); T = A_1 ... A_N; tip = origin of frame N"
_SPLIT = re.compile(r"[,;\s]+")


def read_points(path: str | Path) -> np.ndarray:
    """Task points ``(m, 3)`` from a CSV/text file: one ``x, y, z`` per line (comma,
    semicolon or whitespace separated), ``#`` comments, an optional header line."""
    path = Path(path)
    try:
        lines = path.read_text(encoding="utf-8").splitlines()
    except (OSError, UnicodeDecodeError) as err:
        raise InputError(
            f"{path}: cannot read the task-point file ({getattr(err, 'strerror', None) or err})"
        ) from None
    rows, header_allowed = [], True
    for number, line in enumerate(lines, start=1):
        text = line.split("#", 1)[0].strip()
        if not text:
            continue
        cells = [c for c in _SPLIT.split(text) if c]
        values = _numbers(cells)
        if values is None and header_allowed:
            header_allowed = False
            continue
        if values is None or len(values) != 3 or not np.all(np.isfinite(values)):
            raise InputError(
                f"{path}: line {number}: expected 3 finite numbers (x, y, z), got {text!r}"
            )
        rows.append(values)
        header_allowed = False
    if not rows:
        raise InputError(f"{path}: no task points (expected lines of x, y, z)")
    return np.array(rows)


def _numbers(cells: list[str]) -> list[float] | None:
    try:
        return [float(c) for c in cells]
    except ValueError:
        return None


def _joints_argument(text: str) -> str | int:
    """``--joints``: an R/P string or a number of joints, checked before any work."""
    stripped = text.strip()
    joints = int(stripped) if stripped.isdigit() else stripped
    configurations(joints, "--joints")
    return joints if isinstance(joints, int) else joints.upper()


def _payload(
    synthesis: DHSynthesis, report: dict, results: dict, settings: DHSynthesisSettings
) -> dict:
    types, table = synthesis.types, synthesis.table
    revolute = [c == "R" for c in types]
    targets = [
        {
            "point": p.tolist(),
            "q": q.tolist(),
            "position": x.tolist(),
            "residual": float(r),
            "manipulability": float(w),
        }
        for p, q, x, r, w in zip(
            synthesis.targets,
            synthesis.q,
            report["positions"],
            report["residual"],
            report["manipulability"],
        )
    ]
    return {
        "convention": CONVENTION,
        "joints": types,
        "a": [float(v) for v in table.a],
        "alpha": [float(v) for v in table.alpha],
        "d": [float(v) if r else None for v, r in zip(table.offset, revolute)],
        "theta": [None if r else float(v) for v, r in zip(table.offset, revolute)],
        "summary": {
            "mean_manipulability": float(np.mean(report["manipulability"])),
            "min_manipulability": float(np.min(report["manipulability"])),
            "max_residual": float(np.max(report["residual"])),
            "reached": int(np.sum(report["residual"] <= settings.reach_tolerance)),
            "targets": len(targets),
            "size": synthesis.size,
            "cost_eq10": synthesis.cost,
            "seconds": synthesis.seconds,
            "measured_on": "the engine's Mechanism (arm.toml): linkopt.solve_fk and manipulability from its sensitivities",
            "stage1_at_user_precision": synthesis.stage1,
        },
        "settings": {
            k: getattr(settings, k)
            for k in (
                "precision",
                "size_damping",
                "b",
                "starts",
                "seed",
                "max_iterations",
                "reach_tolerance",
            )
        },
        "rest_q": rest_configuration(synthesis).tolist(),
        "configurations": {t: s.summary() for t, s in results.items()},
        "mechanism_file": "arm.toml",
        "targets": targets,
    }


def draw(
    synthesis: DHSynthesis, path: str | Path, count: int = 4, title: str = ""
) -> Path:
    """PNG of the task points and the arm (links through the DH frame origins) at
    ``count`` targets spread over the list; headless matplotlib."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    types, table = synthesis.types, dh.DHTable(*synthesis.table)
    fig = plt.figure(figsize=(7, 6))
    ax = fig.add_subplot(projection="3d")
    pts = synthesis.targets
    ax.scatter(
        *pts.T,
        c=synthesis.manipulability,
        cmap="viridis",
        s=14,
        label="task points (colour = w)",
    )
    picks = np.unique(
        np.linspace(0, len(pts) - 1, min(count, len(pts))).round().astype(int)
    )
    drawn = [pts, np.zeros((1, 3))]
    for k, i in enumerate(picks):
        origins = np.asarray(dh.frames(types, table, synthesis.q[i]))[:, :3, 3]
        drawn.append(origins)
        ax.plot(
            *origins.T,
            "-o",
            lw=2.5,
            ms=4,
            color=plt.cm.tab10(k),
            label=f"target {i}: w = {synthesis.manipulability[i]:.3f}",
        )
    ax.scatter([0], [0], [0], marker="s", s=60, color="k", label="base (frame 0)")
    _equal_axes(ax, np.concatenate(drawn))
    ax.set_xlabel("x")
    ax.set_ylabel("y")
    ax.set_zlabel("z")
    ax.set_title(
        title
        or f"{types}: mean w {np.mean(synthesis.manipulability):.3f}, min {np.min(synthesis.manipulability):.3f}, size {synthesis.size:.3f}",
        fontsize=10,
    )
    ax.legend(fontsize=7, loc="upper left")
    fig.tight_layout()
    path = Path(path)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def _equal_axes(ax, points: np.ndarray) -> None:
    """Same scale on x, y and z (a cube around everything drawn)."""
    centre, half = (
        (points.max(axis=0) + points.min(axis=0)) / 2,
        (points.max(axis=0) - points.min(axis=0)).max() / 2 or 1.0,
    )
    for setter, c in zip((ax.set_xlim, ax.set_ylim, ax.set_zlim), centre):
        setter(c - half, c + half)
    ax.set_box_aspect((1, 1, 1))


def _progress(types: str, synthesis: DHSynthesis) -> None:
    s = synthesis.summary()
    print(
        f"  {types}: mean w {s['mean_manipulability']:.4f}, min w {s['min_manipulability']:.4f}, max residual {s['max_residual']:.1e}, size {s['size']:.4f} ({synthesis.seconds:.1f} s)",
        file=sys.stderr,
        flush=True,
    )


def run(args) -> int:
    checks.seed(args.seed, "--seed")
    checks.count(args.starts, "--starts")
    checks.count(args.iterations, "--iterations")
    points = read_points(args.points)
    joints = _joints_argument(args.joints)
    settings = DHSynthesisSettings(
        precision=args.precision,
        size_damping=args.size_damping,
        seed=args.seed,
        starts=args.starts,
        max_iterations=args.iterations,
    )
    out = checks.output_directory(args.out)
    print(
        f"linkopt arm manipulability: {len(points)} points, joints {joints}, ε = {settings.precision:g}, ξ = {settings.size_damping:g}, {settings.starts} starts",
        file=sys.stderr,
        flush=True,
    )
    best, results = synthesize_dh(points, joints, settings, progress=_progress)
    print(
        f"  measuring {best.types} on the engine's mechanism ...",
        file=sys.stderr,
        flush=True,
    )
    _, text, report = engine_report(
        best, name=f"{best.types} arm from {Path(args.points).name}"
    )
    header = f"# DH arm synthesised by `linkopt arm manipulability` (paper 004) from {Path(args.points).name}\n# rest pose: joint values {rest_configuration(best).tolist()}; motors are measured from it\n"
    (out / "arm.toml").write_text(header + text, encoding="utf-8")
    payload = _payload(best, report, results, settings)
    (out / "dh.json").write_text(json.dumps(payload, indent=2), encoding="utf-8")
    draw(best, out / "manipulability.png")
    s = payload["summary"]
    print(
        f"{best.types}: mean w {s['mean_manipulability']:.4f}, min w {s['min_manipulability']:.4f}, max residual {s['max_residual']:.2e} ({s['reached']}/{s['targets']} reached), size {s['size']:.4f}"
    )
    print(f"wrote {out / 'dh.json'}, {out / 'arm.toml'}, {out / 'manipulability.png'}")
    if s["reached"] < s["targets"]:
        print(
            f"linkopt: warning: {s['targets'] - s['reached']} target(s) not reached within {settings.reach_tolerance:g} (a {len(best.types)}-joint arm may not reach them at all)",
            file=sys.stderr,
        )
    return 0 if bool(report["converged"].all()) and s["reached"] == s["targets"] else 1


def register(arm_subparsers) -> None:
    """Add ``manipulability`` to ``linkopt arm``."""
    p = arm_subparsers.add_parser(
        "manipulability",
        help="synthesise a DH arm for task points (max manipulability, paper 004)",
    )
    p.add_argument(
        "points",
        help="CSV/text file of task points, one 'x, y, z' per line (optional header, # comments)",
    )
    p.add_argument(
        "--joints",
        default="RRR",
        help="joint types such as RRR or RPR, or a number N to try all 2^N R/P strings (default RRR)",
    )
    p.add_argument(
        "--out",
        required=True,
        help="output directory (dh.json, arm.toml, manipulability.png)",
    )
    p.add_argument(
        "--precision", type=float, default=25.0, help="ε of eq. 8-10 (default 25)"
    )
    p.add_argument(
        "--size-damping", type=float, default=12.0, help="ξ of eq. 9-10 (default 12)"
    )
    p.add_argument(
        "--seed",
        type=int,
        default=0,
        help="seed of the multi-start initial guesses (default 0)",
    )
    p.add_argument(
        "--starts", type=int, default=8, help="number of seeded starts (default 8)"
    )
    p.add_argument(
        "--iterations",
        type=int,
        default=4000,
        help="L-BFGS iteration cap per minimisation (default 4000)",
    )
    p.set_defaults(run=run)
