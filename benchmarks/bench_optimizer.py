"""End-to-end optimisation of a paper example (Sec. VI, Table I): iterations, time,
result.

Run:
``.venv/bin/python benchmarks/bench_optimizer.py [--mechanism five_bar] [--seeds
0,1,...,7] [--workers 1,2]`` (``--mechanism``: ``five_bar``, ``finger`` or
``neck_2dof``, the file of that name in ``mechanisms/``)

For each worker count, with a fresh compilation cache: runs ``linkopt optimize`` for the
first seed twice (cold cache, then warm) and every other seed once (warm), each in a
fresh process (20 particles, hybrid PSO + partial gradient) into a temporary directory,
and prints the iterations and design evaluations, the optimiser's wall time (and how
much of it iteration 0, which carries the start-up, took, and the mean of the others),
the whole command's wall time (compilation, verification, plots), the final ``f_design``
and whether ``linkopt verify`` passes on the result, then the median over the warm runs.
Baseline: the paper's Table I for that mechanism (:data:`PAPER`: iterations and
seconds; C++, 4 cores). Writes every run and the medians to
``benchmarks/results/bench_optimizer.json`` (the five-bar) or
``bench_optimizer_<mechanism>.json``.

The number of swarm iterations a seed needs varies a lot from seed to seed, and a change
anywhere in the evaluation can move every seed's count, so compare medians over many
seeds, not one seed's time. The worker split this measures (``--workers 1,2``) is
documented in :mod:`linkopt._design.workers`.
"""

from __future__ import annotations

import argparse
import csv
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import _results
import numpy as np

ROOT = Path(__file__).resolve().parent.parent
#: The paper's Table I: swarm iterations and seconds of each example measured here.
PAPER = {
    "five_bar": (8, 15 * 60),
    "finger": (21, 65 * 60),
    "neck_2dof": (25, 55 * 60),
}
PAPER_ITERATIONS, PAPER_SECONDS = PAPER["five_bar"]
FILE = ROOT / "mechanisms/five_bar.toml"


def run(seed: int, workers: int, cache: Path) -> dict:
    with tempfile.TemporaryDirectory() as out:
        began = time.perf_counter()
        cmd = [
            sys.executable,
            "-m",
            "linkopt",
            "optimize",
            str(FILE),
            "--out",
            out,
            "--seed",
            str(seed),
            "--workers",
            str(workers),
        ]
        env = {**os.environ, "LINKOPT_CACHE_DIR": str(cache)}
        done = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, env=env)
        if done.returncode not in (0, 1):  # 1: finished, but not verified
            raise RuntimeError(f"{' '.join(cmd)} failed:\n{done.stderr}")
        seconds = time.perf_counter() - began
        summary = json.loads((Path(out) / "summary.json").read_text())
        with open(Path(out) / "history.csv") as f:
            times = [float(row["wall_time"]) for row in csv.DictReader(f)]
    # iteration 0 carries the start-up (worker processes, loading executables)
    per_iteration = (
        (times[-1] - times[0]) / (len(times) - 1) if len(times) > 1 else float("nan")
    )
    return {
        "seed": seed,
        "seconds": seconds,
        "first": times[0],
        "per_iteration": per_iteration,
        **{
            k: summary[k]
            for k in (
                "iterations",
                "evaluations",
                "f_design",
                "regularizer",
                "verified",
                "wall_time",
            )
        },
    }


def _line(workers: int, label: str, r: dict) -> str:
    """One run's report line."""
    return (
        f"  workers {workers}, seed {r['seed']}, {label} cache:"
        f" {r['iterations']:3d} iterations ({r['evaluations']} design evaluations),"
        f" optimiser {r['wall_time']:6.1f} s (iteration 0 {r['first']:5.1f} s,"
        f" then {r['per_iteration']:4.2f} s each),"
        f" whole command {r['seconds']:6.1f} s,"
        f" f_design {r['f_design']:.2e}, verified {r['verified']}"
        f"  (paper/optimiser {PAPER_SECONDS / r['wall_time']:.0f}x,"
        f" paper/command {PAPER_SECONDS / r['seconds']:.1f}x)"
    )


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--mechanism", default="five_bar", choices=sorted(PAPER))
    parser.add_argument("--seeds", default="0,1,2,3,4,5,6,7")
    parser.add_argument(
        "--workers", default="1,2", help="comma-separated worker counts to compare"
    )
    args = parser.parse_args()
    global FILE, PAPER_ITERATIONS, PAPER_SECONDS
    FILE = ROOT / "mechanisms" / f"{args.mechanism}.toml"
    PAPER_ITERATIONS, PAPER_SECONDS = PAPER[args.mechanism]
    print(
        f"{args.mechanism} optimisation; paper: {PAPER_ITERATIONS} iterations,"
        f" {PAPER_SECONDS / 60:.0f} min"
    )
    runs, medians = [], []
    for workers in (int(w) for w in args.workers.split(",")):
        warm = []
        with tempfile.TemporaryDirectory() as cache:
            for seed in (int(s) for s in args.seeds.split(",")):
                for label in (
                    ("cold", "warm")
                    if seed == int(args.seeds.split(",")[0])
                    else ("warm",)
                ):
                    r = run(seed, workers, Path(cache))
                    if label == "warm":
                        warm.append(r)
                    print(_line(workers, label, r), flush=True)
                    runs.append(_row(workers, label, r))
        if warm:
            iterations = float(np.median([r["iterations"] for r in warm]))
            seconds = float(np.median([r["wall_time"] for r in warm]))
            verified = sum(bool(r["verified"]) for r in warm)
            print(
                f"  workers {workers}, median of {len(warm)} warm runs:"
                f" {iterations:.1f} iterations, optimiser {seconds:.1f} s"
                f" (paper/optimiser {PAPER_SECONDS / seconds:.0f}x),"
                f" {verified} of {len(warm)} verified",
                flush=True,
            )
            medians.append(
                {
                    "workers": workers,
                    "warm_runs": len(warm),
                    "iterations": iterations,
                    "optimiser_s": seconds,
                    "paper_over_optimiser": PAPER_SECONDS / seconds,
                    "verified": verified,
                }
            )
    name = "bench_optimizer" + (
        "" if args.mechanism == "five_bar" else f"_{args.mechanism}"
    )
    _results.write(
        Path(__file__).with_name(f"{name}.py"),
        {
            "mechanism": args.mechanism,
            "paper": {"iterations": PAPER_ITERATIONS, "seconds": PAPER_SECONDS},
            "medians_of_warm_runs": medians,
            "runs": runs,
        },
    )


def _row(workers: int, label: str, r: dict) -> dict:
    """One run as a row of the results file."""
    return {
        "workers": workers,
        "seed": r["seed"],
        "cache": label,
        "iterations": r["iterations"],
        "evaluations": r["evaluations"],
        "optimiser_s": r["wall_time"],
        "iteration_0_s": r["first"],
        "per_iteration_s": r["per_iteration"],
        "command_s": r["seconds"],
        "f_design": r["f_design"],
        "verified": r["verified"],
    }


if __name__ == "__main__":
    main()
