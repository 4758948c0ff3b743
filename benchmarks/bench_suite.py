"""The paper's mechanism suite (paper 001, Sec. VI, Table I): sizes, iterations, time.

Run: ``.venv/bin/python benchmarks/bench_suite.py [--runs runs/suite]
[--only finger,neck_2dof]``

For each mechanism, runs ``linkopt optimize FILE --out RUNS/NAME --resume`` in a fresh
process (default settings: 20 particles, hybrid PSO + partial gradient, seed 0), so a
killed benchmark continues where it stopped and a finished run is only read back. Then
prints a table beside Table I: |s|, |p|, IK targets, iterations, the optimiser's wall
time, the whole command's wall time (compilation, verification and plots included) and
the ratio of the paper's time to ours, and writes the table to
``benchmarks/results/bench_suite.json`` (a run only read back has no command time).
Baseline: Table I (``PAPER``; C++, Intel i7-7700, 4 cores).
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from pathlib import Path

import _results

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

import linkopt  # noqa: E402
from linkopt._design.evaluation import targets  # noqa: E402

# name: (|s|, |p|, targets, iterations, seconds) from the paper's Table I
PAPER = {
    "five_bar": (35, 3, 9, 8, 15 * 60),
    "finger": (49, 12, 9, 21, 65 * 60),
    "neck_2dof": (42, 6, 9, 25, 55 * 60),
    "jansen_2dof": (63, 12, 16, 38, 13 * 3600),
    "neck_3dof": (56, 6, 27, 52, 18.5 * 3600),
}


def run(name: str, runs: Path) -> dict:
    out = runs / name
    summary = out / "summary.json"
    seconds = None
    if not summary.exists():
        began = time.perf_counter()
        cmd = [
            sys.executable,
            "-m",
            "linkopt",
            "optimize",
            str(ROOT / "mechanisms" / f"{name}.toml"),
            "--out",
            str(out),
        ]
        if (out / "checkpoint.json").exists():
            cmd.append("--resume")
        if subprocess.run(cmd, cwd=ROOT).returncode not in (0, 1):  # 1: not verified
            raise RuntimeError(f"{' '.join(cmd)} failed")
        seconds = time.perf_counter() - began
    return {"seconds": seconds, **json.loads(summary.read_text())}


def _row(name: str, mech, r: dict) -> str:
    """One mechanism's line of the table, the paper's values in parentheses."""
    s, p, t, iterations, seconds = PAPER[name]
    command = "-" if r["seconds"] is None else f"{r['seconds']:.0f} s"
    return (
        f"{name:12} {mech.state_size:>3} ({s:>2}) {mech.design.size:>2} ({p:>2})"
        f" {len(targets(mech)):>3} ({t:>2})"
        f" {r['iterations']:>4} ({iterations:>2}) {r['wall_time']:>8.0f} s"
        f" {command:>9} {seconds / 60:>6.0f} min"
        f" {seconds / r['wall_time']:>6.0f}x  {r['verified']}"
    )


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument(
        "--runs",
        default=str(ROOT / "runs" / "suite"),
        help="directory of the run directories",
    )
    parser.add_argument(
        "--only", default=",".join(PAPER), help="comma-separated mechanism names"
    )
    args = parser.parse_args()
    rows = []
    for name in args.only.split(","):
        mech = linkopt.load(ROOT / "mechanisms" / f"{name}.toml")
        result = run(name, Path(args.runs))
        rows.append((name, mech, result))
    print(
        f"{'mechanism':12} {'|s|':>8} {'|p|':>6} {'targets':>8} {'iterations':>11}"
        f" {'optimiser':>10} {'command':>9} {'paper':>8} {'ratio':>7}  verified"
    )
    for name, mech, r in rows:
        print(_row(name, mech, r))
    print(
        "(paper's Table I values in parentheses;"
        " ratio = paper's time / our optimiser wall time)"
    )
    _results.write(
        __file__, {"mechanisms": [_record(name, mech, r) for name, mech, r in rows]}
    )


def _record(name: str, mech, r: dict) -> dict:
    """One mechanism's row of the results file, the paper's values beside ours."""
    s, p, t, iterations, seconds = PAPER[name]
    return {
        "mechanism": name,
        "state_size": mech.state_size,
        "paper_state_size": s,
        "design_size": mech.design.size,
        "paper_design_size": p,
        "targets": len(targets(mech)),
        "paper_targets": t,
        "iterations": r["iterations"],
        "paper_iterations": iterations,
        "optimiser_s": r["wall_time"],
        "command_s": r["seconds"],
        "paper_s": seconds,
        "paper_over_optimiser": seconds / r["wall_time"],
        "verified": r["verified"],
    }


if __name__ == "__main__":
    main()
