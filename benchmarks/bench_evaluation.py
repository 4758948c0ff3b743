"""Design-evaluation speed (paper Sec. IV): one five-bar design (9 targets) and 20 at
once.

Run: ``.venv/bin/python benchmarks/bench_evaluation.py``

Prints the warm time of one evaluation and of a batch of 20 designs (one vmapped call),
and the compile time of each with a cold and a warm persistent cache (fresh processes).
Baseline: a prototype stand-in (20 designs x 18 samples x 30 fixed BFGS steps) took
3.5 s per batch, 50 s to compile cold and 2 s with a warm cache; target <= 1 s a batch.

Figures behind the design choices (measured when each was made):

* Traced programs on disk (``linkopt._engine.programs``): tracing and lowering the
  batched five-bar evaluation took 5.9 s, against 2.1 s to load its executable from the
  compilation cache; every optimiser run and worker process paid it again.
* One step function for both phases of the sample queue (``linkopt._design.sampling``):
  the program that held the expensive evaluation four times (IK start and step,
  adversarial start and step) took 2.0 s to load from the compilation cache and 27 s to
  compile for 10 five-bar designs, against 0.6 s and 9 s with the shared step.
* Plain-JAX linear algebra (:mod:`linkopt._engine.dense`) instead of LAPACK calls, and
  XLA's default thread pool instead of ``PJRT_NPROC=1``: 20 five-bar designs
  (``p0`` + N(0, 1) offsets, seed 0), best of two warm calls, 37.2 s -> 5.7 s on the
  shared 2-core machine at load average 8.5 and 11.6 (first call in a fresh process
  116 s -> 114 s). The load was far too high for absolute figures; rerun on a quiet
  machine.
* ``QUEUE_WIDTH`` = 12 (``linkopt._design.evaluation``): ten five-bar designs (90
  lanes) took 0.83-0.87 s at widths 6-15, 0.97 s at 45 and 1.14 s at 90; ten 3-motor
  neck designs (270 lanes) 5.9-6.5 s at 8 and 15, 6.7 s at 45 and 8.1-9.1 s at 135.
  Re-measured with the plain-JAX linear algebra (2026-12-03, idle machine, ten
  five-bar designs): 2.74 s at width 12, 2.83 s at 24, 3.21 s at 48, so 12 stays.
* The cyclic Jacobi eigen-solver of σ_min's 6 x 6 Ritz matrix
  (:func:`linkopt._engine.dense.symmetric_eigh`): each rotation now updates only rows
  and columns ``p`` and ``q``, where it formed the rotation ``G`` and took three 6 x 6
  matrix products. For the 24 matrices of a 12-slot queue step, 2.2 ms -> 0.58 ms
  alone, and σ_min with its gradient 4.9 ms -> about 2.2 ms a step; ten five-bar
  designs 2.74 s -> 2.2-2.9 s (2026-12-03, idle machine; the spread is run-to-run
  noise on the shared VM). Unrolling each sweep's 15 rotations with static ``(p, q)``
  was 0.25 ms alone, but inside the evaluation no faster (2.41-2.53 s against
  2.20-2.53 s, same process, alternating) and its compilation 3 s slower (29.1 s
  against 26.3 s); the loop form compiles the 10-design evaluation in 20.2 s.
"""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
FILE = ROOT / "mechanisms/five_bar.toml"
BASELINE_BATCH_S = 3.5
TARGET_BATCH_S = 1.0

FIRST_CALL = """
import time, numpy as np, jax, linkopt
from linkopt._design.evaluation import evaluate
m = linkopt.load({path!r})
rng = np.random.default_rng(0)
designs = np.asarray(m.design.p0) + rng.normal(0, 1.0, ({n}, m.design.size))
t = time.perf_counter()
jax.block_until_ready(evaluate(m, designs if {n} > 1 else None))
print(time.perf_counter() - t)
"""


def first_call_seconds(cache: str, n: int) -> float:
    env = dict(os.environ, LINKOPT_CACHE_DIR=cache)
    code = FIRST_CALL.format(path=str(FILE), n=n)
    out = subprocess.run(
        [sys.executable, "-c", code],
        env=env,
        capture_output=True,
        text=True,
        check=True,
    )
    return float(out.stdout.strip().splitlines()[-1])


def main() -> None:
    import jax
    import numpy as np

    import linkopt
    from linkopt._design.evaluation import evaluate

    mech = linkopt.load(FILE)
    designs = np.asarray(mech.design.p0) + np.random.default_rng(0).normal(
        0, 1.0, (20, mech.design.size)
    )
    timings = {}
    for label, arg, repeats in (("one design", None, 5), ("20 designs", designs, 3)):
        jax.block_until_ready(evaluate(mech, arg))
        start = time.perf_counter()
        for _ in range(repeats):
            jax.block_until_ready(evaluate(mech, arg))
        timings[label] = (time.perf_counter() - start) / repeats
    with tempfile.TemporaryDirectory() as cache:
        cold = [first_call_seconds(cache, n) for n in (1, 20)]
        warm = [first_call_seconds(cache, n) for n in (1, 20)]
    print(f"five-bar design evaluation, 9 targets, {os.cpu_count()} cores")
    print(f"  one design                {timings['one design']:8.3f} s")
    batch = timings["20 designs"]
    print(
        f"  20 designs (one call)     {batch:8.3f} s   target <= {TARGET_BATCH_S} s,"
        f" prototype baseline {BASELINE_BATCH_S} s"
        f" (ratio {BASELINE_BATCH_S / batch:.2f}x)"
    )
    print(
        f"  first call, one design    cold cache {cold[0]:6.1f} s,"
        f" warm cache {warm[0]:6.1f} s (includes tracing)"
    )
    print(
        f"  first call, 20 designs    cold cache {cold[1]:6.1f} s,"
        f" warm cache {warm[1]:6.1f} s"
    )


if __name__ == "__main__":
    main()
