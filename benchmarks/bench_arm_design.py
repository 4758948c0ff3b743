"""Solve times of the two arm examples over 8 seeds, beside the paper's means.

Paper 000 (MATLAB fmincon with MEX inner loops, 4-core i5) gives a mean time per solve
over 8 random seeds for each arm (``PAPER_MINUTES``). Here: SLSQP with exact JAX
gradients, one process, one XLA thread. Compilation (once per arm, then kept in the
persistent cache) is reported separately from the per-seed solve times.

    nice -n 10 .venv/bin/python benchmarks/bench_arm_design.py [backpack|rover ...]
    [--starts N]

Writes ``benchmarks/results/bench_arm_design.json`` and the figures
``figures/arm_<task>.png`` of the best solution of each task.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import _results
import numpy as np

import linkopt
from linkopt._arms.codesign import multistart, nlp
from linkopt._arms.codesign.task import load_task
from linkopt._draw.arms.codesign import plot_solution

linkopt.use_cache()  # float64, and compiled programs kept on disk
ROOT = Path(__file__).resolve().parent.parent
#: The paper's mean minutes per solve over 8 random seeds (paper 000).
PAPER_MINUTES = {"backpack": 1.8, "rover": 85.0}


def bench(name: str, starts: int) -> dict:
    task = load_task(ROOT / "tasks" / f"{name}_arm.toml")
    started = time.perf_counter()
    problem = nlp.prepare(task)
    prepare_s = time.perf_counter() - started
    started = time.perf_counter()
    nlp.evaluate(problem, multistart.initial_point(problem, 0))
    compile_s = time.perf_counter() - started
    runs = []
    for k in range(starts):
        runs.append(
            multistart.solve_from(
                problem, multistart.initial_point(problem, k), start=k
            )
        )
        r = runs[-1]
        print(
            f"{name} seed {k}: {r.seconds:.1f} s, feasible {r.feasible}, objective "
            f"{r.objective:.4g}",
            flush=True,
        )
    best = multistart.best_of(runs)
    plot_solution(
        problem,
        best,
        ROOT / "figures" / f"arm_{name}.png",
        title=f"{task.name}: best of {starts} seeds, objective {best.objective:.4g}",
    )
    mean_min = float(np.mean([r.seconds for r in runs])) / 60
    return {
        "task": name,
        "starts": starts,
        "prepare_s": prepare_s,
        "compile_s": compile_s,
        "mean_solve_min": mean_min,
        "paper_mean_min": PAPER_MINUTES[name],
        "ratio_paper_over_ours": PAPER_MINUTES[name] / mean_min,
        "feasible": sum(r.feasible for r in runs),
        "best_objective": best.objective,
        "best_feasible": best.feasible,
        "seconds": [r.seconds for r in runs],
        "iterations": [r.iterations for r in runs],
    }


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("tasks", nargs="*", default=["backpack", "rover"])
    parser.add_argument("--starts", type=int, default=8)
    args = parser.parse_args()
    results = [bench(name, args.starts) for name in args.tasks]
    _results.write(__file__, {"tasks": results})
    for r in results:
        print(
            f"{r['task']}: mean {r['mean_solve_min']:.2f} min per seed (paper "
            f"{r['paper_mean_min']} min, ratio {r['ratio_paper_over_ours']:.1f}x), "
            f"{r['feasible']}/{r['starts']} feasible, compile {r['compile_s']:.0f} s"
        )
    print("figures: " + ", ".join(f"figures/arm_{r['task']}.png" for r in results))


if __name__ == "__main__":
    main()
