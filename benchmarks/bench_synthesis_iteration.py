"""The synthesis objective's hot path (issue 41): one iteration's batched score of a
64-design swarm over a 360-row cycle of the four-bar
(``mechanisms/four_bar_path.toml``), warm, and its partial gradient; target 0.5 s for
the score on a 2-core machine.

Run: ``.venv/bin/python benchmarks/bench_synthesis_iteration.py [--repeat N]``; the
figures go to ``benchmarks/results/bench_synthesis_iteration.json`` with the date,
machine, commit and the load average while it ran (a shared machine reads slow).
"""

from __future__ import annotations

import argparse
import os
import time
from pathlib import Path

import _results
import numpy as np

import linkopt
from linkopt._design.evaluation import alpha_minus
from linkopt._synth import objective
from linkopt.synthesis import load_targets

ROOT = Path(__file__).resolve().parent.parent
DESIGNS, STEPS, TARGET = 64, 360, 0.5


def _timed(fn, repeat: int) -> tuple[float, float, float]:
    """The first call's seconds (compile or load included), the best warm one, and
    that call's CPU seconds (all threads: on a shared machine, wall time above CPU
    time over the cores is time spent waiting for them)."""
    start = time.perf_counter()
    fn()
    first = time.perf_counter() - start
    warm = []
    for _ in range(repeat):
        start, cpu = time.perf_counter(), time.process_time()
        fn()
        warm.append((time.perf_counter() - start, time.process_time() - cpu))
    best = min(warm)
    return first, best[0], best[1]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args()
    mech = linkopt.load(ROOT / "mechanisms" / "four_bar_path.toml")
    targets = load_targets(mech)
    problem = objective.Problem(targets, objective.plan(mech, targets, STEPS))
    alpha = alpha_minus(mech)
    rng = np.random.default_rng(0)
    d = mech.design
    designs = d.p0 + rng.uniform(-0.1, 0.1, (DESIGNS, d.size)) * (d.upper - d.lower)
    designs = np.clip(designs, d.lower, d.upper)

    def score():
        return objective.score(mech, problem, designs, alpha).total.block_until_ready()

    scored = objective.score(mech, problem, designs, alpha)

    def gradient():
        return objective.gradients(mech, problem, designs, scored, alpha)

    first, warm, cpu = _timed(score, args.repeat)
    grad_first, grad_warm, _ = _timed(gradient, args.repeat)
    figures = {
        "designs": DESIGNS,
        "rows": STEPS,
        "score_first_s": first,
        "score_warm_s": warm,
        "score_warm_cpu_s": cpu,
        "gradient_first_s": grad_first,
        "gradient_warm_s": grad_warm,
        "target_s": TARGET,
        "load_average": os.getloadavg()[0],
    }
    print(
        f"score of {DESIGNS} designs x {STEPS} rows: warm {warm:.3f} s "
        f"({cpu:.3f} CPU s) "
        f"(target {TARGET} s; first {first:.1f} s); gradient warm {grad_warm:.3f} s; "
        f"load average {figures['load_average']:.1f}"
    )
    print(_results.write(__file__, figures))


if __name__ == "__main__":
    main()
