"""Design-evaluation speed (paper Sec. IV): one five-bar design (9 targets) and 20 at
once.

Run: ``.venv/bin/python benchmarks/bench_evaluation.py``

Prints the warm time of one evaluation and of a batch of 20 designs (one vmapped call),
and the compile time of each with a cold and a warm persistent cache (fresh processes),
against the target ``TARGET_BATCH_S`` and the ``BASELINE_*`` figures of a prototype
stand-in (20 designs x 18 samples x 30 fixed BFGS steps), and writes them to
``benchmarks/results/bench_evaluation.json``.

The choices behind the time it measures are documented where they are made: the
queue's width (``QUEUE_WIDTH`` in :mod:`linkopt._design.evaluation`), one step
function for both sample phases (:mod:`linkopt._design.sampling`), plain-JAX linear
algebra and the Jacobi eigen-solver (:mod:`linkopt._engine.dense`), traced programs on
disk (:mod:`linkopt._engine.programs`).
"""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import _results

ROOT = Path(__file__).resolve().parent.parent
FILE = ROOT / "mechanisms/five_bar.toml"
#: The prototype stand-in's seconds per batch of 20 designs, and to compile it from an
#: empty and from a warm cache.
BASELINE_BATCH_S = 3.5
BASELINE_COMPILE_COLD_S = 50.0
BASELINE_COMPILE_WARM_S = 2.0
#: Seconds per batch of 20 designs.
TARGET_BATCH_S = 1.0

FIRST_CALL = """
import time, numpy as np, jax, linkopt
from linkopt._design.evaluation import evaluate
linkopt.use_cache()
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
    _results.write(
        __file__,
        {
            "mechanism": "five_bar",
            "targets": 9,
            "warm": [
                {"designs": 1, "seconds": timings["one design"]},
                {
                    "designs": 20,
                    "seconds": batch,
                    "target_s": TARGET_BATCH_S,
                    "baseline_s": BASELINE_BATCH_S,
                },
            ],
            "first_call": [
                {"designs": 1, "cold_cache_s": cold[0], "warm_cache_s": warm[0]},
                {
                    "designs": 20,
                    "cold_cache_s": cold[1],
                    "warm_cache_s": warm[1],
                    "baseline_cold_s": BASELINE_COMPILE_COLD_S,
                    "baseline_warm_s": BASELINE_COMPILE_WARM_S,
                },
            ],
        },
    )


if __name__ == "__main__":
    main()
