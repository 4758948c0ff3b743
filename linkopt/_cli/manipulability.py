"""``linkopt arm manipulability POINTS --joints RRR|N --out DIR``: DH synthesis
(paper 004).

Writes ``DIR/dh.json`` (the DH table in the distal convention, per target the joint
values, residual and manipulability measured on the engine's Mechanism),
``DIR/arm.toml`` (the equivalent mechanism file, accepted by ``linkopt check`` / ``fk``)
and ``DIR/manipulability.png`` (the arm at a few targets with the point cloud). Progress
lines go to stderr; the summary to stdout.

The command holds the lock on ``DIR`` (:mod:`linkopt._folders`) from before the
synthesis until its files are written: a second command on the same ``DIR`` exits 2
naming the first. The three files are written to a staging folder inside ``DIR`` and
moved in together once all are written, ``dh.json`` last; a command that fails or is
killed before that leaves none of them.

Exit status: 0 when every target is reached (residual on the engine's mechanism within
the reach tolerance, 1e-3), 1 when some are not or an engine FK solve fails (the files
are still written), 2 on bad input (one ``linkopt: error: ...`` line on stderr).
"""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from .._arms import checks
from .._arms.dh.points import read_points
from .._arms.dh.settings import LIMITS, DHSynthesisSettings
from .._folders import run_folder, staged
from .options import Option, add_options, settings_of

if TYPE_CHECKING:
    from .._arms.dh.synthesis import DHSynthesis

#: The options that set :class:`~linkopt.arms.dh.DHSynthesisSettings` fields.
OPTIONS = (
    Option("--precision", "precision", "ε of eq. 8-10"),
    Option("--size-damping", "size_damping", "ξ of eq. 9-10"),
    Option("--seed", "seed", "seed of the multi-start initial guesses"),
    Option("--starts", "starts", "number of seeded starts"),
    Option("--iterations", "max_iterations", "L-BFGS iteration cap per minimisation"),
)

CONVENTION = (
    "A_i = Rot_z(theta_i) Trans_z(d_i) Trans_x(a_i) Rot_x(alpha_i) (standard, distal "
    "DH); T = A_1 ... A_N; tip = origin of frame N"
)


def _joints_argument(text: str) -> str | int:
    """``--joints``: an R/P string or a number of joints, checked before any work."""
    from .._arms.dh.synthesis import configurations

    stripped = text.strip()
    joints = int(stripped) if stripped.isdigit() else stripped
    configurations(joints, "--joints")
    return joints if isinstance(joints, int) else joints.upper()


_SETTINGS = (
    "precision",
    "size_damping",
    "b",
    "starts",
    "seed",
    "max_iterations",
    "reach_tolerance",
)


def _targets(synthesis: DHSynthesis, report: dict) -> list[dict]:
    """Per target: the point, joint values, reached position, residual and w."""
    return [
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


def _summary(
    synthesis: DHSynthesis, report: dict, settings: DHSynthesisSettings, targets: int
) -> dict:
    return {
        "mean_manipulability": float(np.mean(report["manipulability"])),
        "min_manipulability": float(np.min(report["manipulability"])),
        "max_residual": float(np.max(report["residual"])),
        "reached": int(np.sum(report["residual"] <= settings.reach_tolerance)),
        "targets": targets,
        "size": synthesis.size,
        "cost_eq10": synthesis.cost,
        "seconds": synthesis.seconds,
        "measured_on": (
            "the engine's Mechanism (arm.toml): linkopt.solve_fk and manipulability "
            "from its sensitivities"
        ),
        "stage1_at_user_precision": synthesis.stage1,
    }


def _payload(
    synthesis: DHSynthesis, report: dict, results: dict, settings: DHSynthesisSettings
) -> dict:
    """The content of ``dh.json``."""
    from .._arms.dh.synthesis import rest_configuration

    types, table = synthesis.types, synthesis.table
    revolute = [c == "R" for c in types]
    targets = _targets(synthesis, report)
    return {
        "convention": CONVENTION,
        "joints": types,
        "a": [float(v) for v in table.a],
        "alpha": [float(v) for v in table.alpha],
        "d": [float(v) if r else None for v, r in zip(table.offset, revolute)],
        "theta": [None if r else float(v) for v, r in zip(table.offset, revolute)],
        "summary": _summary(synthesis, report, settings, len(targets)),
        "settings": {k: getattr(settings, k) for k in _SETTINGS},
        "rest_q": rest_configuration(synthesis).tolist(),
        "configurations": {t: s.summary() for t, s in results.items()},
        "mechanism_file": "arm.toml",
        "targets": targets,
    }


def _progress(types: str, synthesis: DHSynthesis) -> None:
    s = synthesis.summary()
    print(
        f"  {types}: mean w {s['mean_manipulability']:.4f}, min w "
        f"{s['min_manipulability']:.4f}, max residual {s['max_residual']:.1e}, "
        f"size {s['size']:.4f} ({synthesis.seconds:.1f} s)",
        file=sys.stderr,
        flush=True,
    )


def synthesize_dh(points, joints, settings, progress):
    """:func:`linkopt.arms.dh.synthesize`, its module imported on the first call."""
    from .._arms.dh.synthesis import synthesize_dh

    return synthesize_dh(points, joints, settings, progress=progress)


def _check_flags(args) -> None:
    """Every flag meaningful and within :data:`~linkopt._arms.dh.settings.LIMITS`,
    before any work."""
    checks.number(
        args.precision, "--precision", positive=True, maximum=LIMITS["weights"]
    )
    checks.number(args.size_damping, "--size-damping", maximum=LIMITS["weights"])
    checks.seed(args.seed, "--seed")
    checks.count(args.starts, "--starts", maximum=LIMITS["starts"])
    checks.count(args.iterations, "--iterations", maximum=LIMITS["max_iterations"])


def run(args) -> int:
    _check_flags(args)
    joints = _joints_argument(args.joints)
    points = read_points(args.points)
    settings = settings_of(args, DHSynthesisSettings, OPTIONS)
    with run_folder(args.out) as out:
        print(
            f"linkopt arm manipulability: {len(points)} points, joints {joints}, "
            f"ε = {settings.precision:g}, ξ = {settings.size_damping:g}, "
            f"{settings.starts} starts",
            file=sys.stderr,
            flush=True,
        )
        best, results = synthesize_dh(points, joints, settings, progress=_progress)
        print(
            f"  measuring {best.types} on the engine's mechanism ...",
            file=sys.stderr,
            flush=True,
        )
        with staged(out, marker="dh.json") as stage:
            report, payload = _write_files(
                best, results, settings, Path(args.points).name, stage
            )
    s = payload["summary"]
    _print_result(best, s, settings, out)
    return 0 if bool(report["converged"].all()) and s["reached"] == s["targets"] else 1


def _write_files(
    best: DHSynthesis,
    results: dict,
    settings: DHSynthesisSettings,
    source: str,
    out: Path,
) -> tuple[dict, dict]:
    """``arm.toml``, ``dh.json`` and ``manipulability.png``; returns the engine
    report and the ``dh.json`` payload."""
    from .._arms.dh.synthesis import engine_report, rest_configuration
    from .._draw.arms.dh import draw

    _, text, report = engine_report(best, name=f"{best.types} arm from {source}")
    header = (
        "# DH arm synthesised by `linkopt arm manipulability` (paper 004) from "
        f"{source}\n# rest pose: joint values {rest_configuration(best).tolist()}; "
        "motors are measured from it\n"
    )
    (out / "arm.toml").write_text(header + text, encoding="utf-8")
    payload = _payload(best, report, results, settings)
    (out / "dh.json").write_text(json.dumps(payload, indent=2), encoding="utf-8")
    draw(best, out / "manipulability.png")
    return report, payload


def _print_result(
    best: DHSynthesis, s: dict, settings: DHSynthesisSettings, out: Path
) -> None:
    print(
        f"{best.types}: mean w {s['mean_manipulability']:.4f}, min w "
        f"{s['min_manipulability']:.4f}, max residual {s['max_residual']:.2e} "
        f"({s['reached']}/{s['targets']} reached), size {s['size']:.4f}"
    )
    print(f"wrote {out / 'dh.json'}, {out / 'arm.toml'}, {out / 'manipulability.png'}")
    if s["reached"] < s["targets"]:
        print(
            f"linkopt: warning: {s['targets'] - s['reached']} target(s) not reached "
            f"within {settings.reach_tolerance:g} (a {len(best.types)}-joint arm may "
            "not reach them at all)",
            file=sys.stderr,
        )


def register(arm_subparsers) -> None:
    """Add ``manipulability`` to ``linkopt arm``."""
    p = arm_subparsers.add_parser(
        "manipulability",
        help="synthesise a DH arm for task points (max manipulability, paper 004)",
    )
    p.add_argument(
        "points",
        help=(
            "CSV/text file of task points, one 'x, y, z' per line (optional header, "
            "# comments)"
        ),
    )
    p.add_argument(
        "--joints",
        default="RRR",
        help=(
            "joint types such as RRR or RPR, or a number N to try all 2^N R/P strings "
            "(default RRR)"
        ),
    )
    p.add_argument(
        "--out",
        required=True,
        help="output directory (dh.json, arm.toml, manipulability.png)",
    )
    add_options(p, DHSynthesisSettings(), OPTIONS)
    p.set_defaults(run=run)
