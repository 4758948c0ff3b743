"""Path, function and motion synthesis against pylinkage 1.3 (issue 41's targets).

Run: ``nice -n 10 .venv/bin/python benchmarks/bench_synthesis.py [--side S,...]
[--timeout SECONDS] [--write-cases]``

Sides (comma-separated, default all):

* ``pylinkage``: ``pylinkage.synthesis.path_generation`` (Burmester over sampled
  coupler orientations, then simulation) on each planar case, in its own process
  under ``--timeout`` (default 60 s): seconds, number of four-bars, best RMS error at
  the points (its ``compute_metrics``) and that solution's least transmission angle.
  pylinkage is an optional dependency (``pip install -e .[bench]``).
* ``start``: linkopt's closed-form start (``linkopt._synth.fourbar.fit_path``, the
  precision-point dyads on at most five of the points), written as a four-bar file
  and swept over its whole cycle (``linkopt._synth.cycle.sweep_cycle``): RMS and
  largest distance at all the points, the first defect, least σ_min, Grashof class
  and least transmission angle.
* ``linkopt``: ``linkopt.synthesis.synthesize(mech, targets, settings)`` on the
  case's file and targets, timed, and its design swept the same way; the command
  recorded is the CLI's equivalent (``linkopt synthesize``).

``--write-cases`` writes each planar case's target points
(``benchmarks/synthesis/<case>.csv``: ``x,y,z`` rows) and its closed-form start
(``benchmarks/synthesis/<case>.toml``) first. Cases pylinkage cannot pose (a foot
path of the Jansen leg, spatial RSSR and spherical four-bars) are listed with the
reason. Results: ``benchmarks/results/bench_synthesis.json``.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from pathlib import Path

import _results
import numpy as np

ROOT = Path(__file__).resolve().parent.parent
CASES_DIR = ROOT / "benchmarks" / "synthesis"
#: The issue's targets for each case (what the comparison must show).
GOALS = {
    "readme_4": "RMS <= pylinkage's best, least transmission >= 30 deg, defect-free, "
    "<= 10 s",
    "arch_5": "RMS <= 1 % of the bounding-box diagonal, defect-free, <= 60 s",
    "d_curve_8": "RMS <= 1 % of the bounding-box diagonal, defect-free, <= 60 s",
    "open_20": "RMS <= 1 % of the bounding-box diagonal, defect-free, <= 60 s",
    "jansen_foot": "from a +-5 % perturbed leg, RMS <= 0.5 % of the stride",
    "rssr_function": "defect-free, verified, RMS <= 1 % of the range",
    "spherical_path": "defect-free, verified, RMS <= 1 % of the range",
}
#: Cases pylinkage (planar four-bars and six-bars from points) cannot pose.
NOT_PLANAR = {
    "jansen_foot": "an eight-link leg driven by one crank: no synthesis of it",
    "rssr_function": "spatial (revolute-spherical-spherical-revolute): planar only",
    "spherical_path": "spherical four-bar: planar only",
}


def planar_cases() -> dict[str, tuple[np.ndarray, bool]]:
    """The planar target curves ``(n, 2)`` and whether each is closed."""
    arch_x = np.linspace(0.0, 4.0, 5)
    d_top = np.radians([90.0, 45.0, 0.0, -45.0, -90.0])
    d_side = np.array([[0.0, -0.5], [0.0, 0.0], [0.0, 0.5]])
    t = np.linspace(0.0, 3.0, 20)
    return {
        # pylinkage's README example
        "readme_4": (np.array([[0, 0], [1, 1], [2, 1], [3, 0]], dtype=float), False),
        "arch_5": (np.c_[arch_x, 1.5 * np.sin(np.pi * arch_x / 4.0)], False),
        # a D: the half circle x = cos, y = sin, then its straight side x = 0
        "d_curve_8": (np.r_[np.c_[np.cos(d_top), np.sin(d_top)], d_side], True),
        "open_20": (np.c_[t, 0.6 * np.sin(1.7 * t) + 0.2 * t], False),
    }


def _rms(distances: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.square(distances))))


# ---------------------------------------------------------------------------------
# pylinkage


def pylinkage_case(name: str) -> dict:
    """One case in this process (the parent runs it under a timeout)."""
    from pylinkage.synthesis import compute_metrics, path_generation

    points = [tuple(map(float, p)) for p in planar_cases()[name][0]]
    start = time.perf_counter()
    result = path_generation(points)
    seconds = time.perf_counter() - start
    metrics = [compute_metrics(s, points) for s in result.solutions]
    best = min(metrics, key=lambda m: m.path_accuracy) if metrics else None
    return {
        "pylinkage_seconds": round(seconds, 3),
        "pylinkage_solutions": len(result.solutions),
        "pylinkage_best_rms": None if best is None else best.path_accuracy,
        "pylinkage_best_least_transmission_deg": (
            None if best is None else best.min_transmission_angle
        ),
        "pylinkage_least_transmission_deg_range": [
            min((m.min_transmission_angle for m in metrics), default=None),
            max((m.min_transmission_angle for m in metrics), default=None),
        ],
        "pylinkage_warning": (result.warnings or [None])[0],
    }


def run_pylinkage(name: str, timeout: float) -> dict:
    command = [sys.executable, __file__, "--pylinkage-case", name]
    start = time.perf_counter()
    try:
        done = subprocess.run(
            command, capture_output=True, text=True, timeout=timeout, check=False
        )
    except subprocess.TimeoutExpired:
        return {
            "pylinkage_seconds": None,
            "pylinkage_status": f"no answer within {timeout:g} s (stopped)",
        }
    if done.returncode != 0:
        tail = (done.stderr.strip().splitlines() or ["?"])[-1]
        return {"pylinkage_status": f"failed: {tail}"}
    out = json.loads(done.stdout.strip().splitlines()[-1])
    out["pylinkage_status"] = "ok"
    out["pylinkage_process_seconds"] = round(time.perf_counter() - start, 3)
    return out


# ---------------------------------------------------------------------------------
# linkopt: the closed-form start, and the synthesiser


def _toml_point(p) -> str:
    return f"[{float(p[0])!r}, {float(p[1])!r}, 0.0]"


#: The least transmission angle each case asks (``[synthesis].min_transmission_deg``):
#: the issue's 30 degrees for pylinkage's README example; 20 for the others, whose
#: goals ask none (at the default 30, no design of arch_5's box meets its points to
#: 1 %: the best of 512 closed-form starts misses by 0.055, see the json's notes).
LEAST_TRANSMISSION = {"readme_4": 30.0, "arch_5": 20.0, "d_curve_8": 20.0,
                      "open_20": 20.0}  # fmt: skip


def four_bar_file(placed, extent: float, case: str, closed: bool) -> str:
    """A four-bar file of a placed four-bar (``linkopt._synth.fourbar``): every
    anchor's x and y and the coupler point free within ``extent`` of it, and a
    ``[synthesis]`` table: the point ``tip`` through the rows of ``CASE.csv``
    beside it, to 1 % of the points' extent."""
    joints = [
        ("A", "ground", "crank", placed.A),
        ("B", "crank", "coupler", placed.B),
        ("C", "coupler", "rocker", placed.C),
        ("D", "ground", "rocker", placed.D),
    ]
    out = ['[mechanism]\nname = "four-bar path"\nground = "ground"\nunits = "mm"\n']
    out += [
        f'[[bodies]]\nname = "{b}"\n' for b in ("ground", "crank", "coupler", "rocker")
    ]
    for name, i, j, p in joints:
        out.append(
            f'[[joints]]\nname = "{name}"\ntype = "revolute"\nbodies = ["{i}", "{j}"]'
            f"\nanchor = {_toml_point(p)}\naxis = [0.0, 0.0, 1.0]\n"
        )
    out.append('[[motors]]\nname = "crank"\njoint = "A"\n')
    out.append(
        f'[[points]]\nname = "tip"\nbody = "coupler"\nposition = '
        f'{_toml_point(placed.P)}\nfollow = "anchors"\n'
    )
    out.append('[[outputs]]\nname = "rocker"\njoint = "D"\nmin = -0.05\nmax = 0.05\n')
    for name, _, _, p in joints:
        for k, axis in enumerate("xy"):
            out.append(
                f'[[parameters]]\nname = "{name}_{axis}"\njoint = "{name}"\n'
                f'coordinate = "{axis}"\nmin = {float(p[k]) - extent!r}\n'
                f"max = {float(p[k]) + extent!r}\n"
            )
    for k, axis in enumerate("xy"):  # the coupler point's place on the coupler
        out.append(
            f'[[parameters]]\nname = "tip_{axis}"\nkind = "point"\npoint = "tip"\n'
            f'coordinate = "{axis}"\nmin = {float(placed.P[k]) - extent!r}\n'
            f"max = {float(placed.P[k]) + extent!r}\n"
        )
    out.append(
        f'[synthesis]\nkind = "path"\nname = "tip"\nfile = "{case}.csv"\n'
        f"closed = {str(closed).lower()}\ntolerance = {0.01 * extent!r}\n"
        f"min_transmission_deg = {LEAST_TRANSMISSION.get(case, 30.0)!r}\n"
    )
    return "\n".join(out)


def _spread(points: np.ndarray, count: int) -> np.ndarray:
    """``count`` of the points, evenly spread along the list (the first kept)."""
    return points[np.round(np.linspace(0, len(points) - 1, count)).astype(int)]


def _targets(points: np.ndarray, closed: bool, tolerance: float):
    from linkopt._synth.targets import Targets

    values = np.c_[points, np.zeros(len(points))]
    return Targets("path", "tip", values, None, closed, tolerance)


def _judge(mech, design, points, closed, extent) -> dict:
    """Sweep a design over its cycle against the points, as
    ``linkopt.synthesis.verify`` does (a crank without limits turns fully, an open
    curve's targets met in cyclic order, the motor either way), with the numbers of
    the planar four-bar."""
    from linkopt._synth import objective
    from linkopt._synth.fourbar import grashof_class, read_four_bar, transmission
    from linkopt._synth.run import verify

    targets = _targets(points, closed, 0.01 * extent)
    problem = objective.Problem(targets, objective.plan(mech, targets))
    result = _Design(
        design if design is not None else mech.design.p0, targets, problem.plan
    )
    report = verify(mech, result)
    four_bar = read_four_bar(mech, design).four_bar()
    return {
        "rms": _rms(report.distances),
        "largest_distance": float(np.max(report.distances)),
        "defect_free": report.defect is None,
        "defect": report.defect,
        "least_sigma": report.least_sigma,
        "alpha_minus": report.alpha_minus,
        "grashof": grashof_class(four_bar),
        "least_transmission_deg": float(np.degrees(transmission(four_bar).worst)),
    }


class _Design:
    """What ``verify`` reads of a synthesis result: the design, targets, plan."""

    def __init__(self, design, targets, plan):
        self.design, self.targets, self.plan = np.asarray(design), targets, plan


def points_csv(points: np.ndarray) -> str:
    """``x,y,z`` rows of planar points (z = 0)."""
    rows = "".join(f"{float(x)!r},{float(y)!r},0.0\n" for x, y in points)
    return "x,y,z\n" + rows


def start_case(name: str, write: bool) -> dict:
    """linkopt's closed-form start for one planar case (the ``start`` side)."""
    import linkopt
    from linkopt._synth.fourbar import fit_path

    points, closed = planar_cases()[name]
    extent = float(np.linalg.norm(np.ptp(points, axis=0)))
    t0 = time.perf_counter()
    fit = fit_path(_spread(points, min(5, len(points))), seed=0, closed=closed)
    seconds = time.perf_counter() - t0
    text = four_bar_file(fit.placed, extent, name, closed)
    if write:
        CASES_DIR.mkdir(parents=True, exist_ok=True)
        (CASES_DIR / f"{name}.toml").write_text(text)
        (CASES_DIR / f"{name}.csv").write_text(points_csv(points))
    source = str(CASES_DIR / f"{name}.toml")  # its [synthesis] file lies beside it
    mech = linkopt.loads(text, source)
    judged = _judge(mech, None, points, closed, extent)
    return {
        "start_seconds": round(seconds, 3),
        "start_fit_residual": fit.residual,
        "start_fit_one_circuit": fit.one_circuit(),
        "start_fit_in_order": fit.in_order(closed),
        **{f"start_{k}": v for k, v in judged.items()},
    }


def linkopt_case(name: str, repeat: int = 2) -> dict:
    """``linkopt.synthesis.synthesize`` on one planar case (the ``linkopt`` side),
    run ``repeat`` times in this process: the first compiles (or loads the
    compiled programs from the disk cache), the last is timed warm; its design
    verified by ``linkopt.synthesis.verify`` (the dense sweep over the same motion:
    an open curve of a crank without limits over its full turn)."""
    import linkopt
    from linkopt import synthesis
    from linkopt._synth.fourbar import grashof_class, read_four_bar, transmission

    command = f"linkopt synthesize benchmarks/synthesis/{name}.toml --seed 0"
    points, _ = planar_cases()[name]
    mech = linkopt.load(CASES_DIR / f"{name}.toml")
    targets = synthesis.load_targets(mech)
    seconds = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        result = synthesis.synthesize(mech, targets, None)
        seconds.append(round(time.perf_counter() - t0, 3))
    report = synthesis.verify(mech, result)
    four_bar = read_four_bar(mech, result.design).four_bar()
    extent = float(np.linalg.norm(np.ptp(points, axis=0)))
    rms = _rms(report.distances)
    return {
        "linkopt_command": command,
        "linkopt_seconds": seconds[-1],
        "linkopt_seconds_first": seconds[0],
        "linkopt_iterations": len(result.history),
        "linkopt_status": "ok",
        "linkopt_rms": rms,
        "linkopt_rms_over_diagonal": rms / extent,
        "linkopt_largest_distance": float(np.max(report.distances)),
        "linkopt_tolerance": targets.tolerance,
        "linkopt_defect_free": report.defect is None,
        "linkopt_defect": report.defect,
        "linkopt_least_sigma": report.least_sigma,
        "linkopt_alpha_minus": report.alpha_minus,
        "linkopt_grashof": grashof_class(four_bar),
        "linkopt_least_transmission_deg": float(
            np.degrees(transmission(four_bar).worst)
        ),
        "linkopt_asked_transmission_deg": targets.min_transmission_deg,
    }


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--side", default="pylinkage,start,linkopt")
    parser.add_argument("--timeout", type=float, default=60.0)
    parser.add_argument("--write-cases", action="store_true")
    parser.add_argument("--cases", default=None, help="comma-separated case names")
    parser.add_argument("--pylinkage-case", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.pylinkage_case:
        print(json.dumps(pylinkage_case(args.pylinkage_case)))
        return
    sides = set(args.side.split(","))
    chosen = set(args.cases.split(",")) if args.cases else set(GOALS)
    rows = []
    for name, (points, closed) in planar_cases().items():
        if name not in chosen:
            continue
        row = {"case": name, "points": len(points), "closed": closed}
        row["goal"] = GOALS[name]
        if "pylinkage" in sides:
            row.update(run_pylinkage(name, args.timeout))
        if "start" in sides:
            row.update(start_case(name, args.write_cases))
        if "linkopt" in sides:
            row.update(linkopt_case(name))
        rows.append(row)
        print(json.dumps(row), flush=True)
    for name, reason in NOT_PLANAR.items():
        if name in chosen:
            rows.append({"case": name, "goal": GOALS[name], "pylinkage_status": reason})
    print(_results.write(__file__, {"timeout_s": args.timeout, "cases": rows}))


if __name__ == "__main__":
    main()
